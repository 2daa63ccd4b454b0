"""Adam (Kingma and Ba, 2015), the update of ``torch.optim.Adam`` without weight decay or amsgrad.

torch's optimisers load ``torch._dynamo`` on their first call (about 2 s of imports per process, paid again by
every training child process); this one is plain tensor arithmetic. Its state dict has torch's layout
(``state``: per parameter index ``step``, ``exp_avg``, ``exp_avg_sq``; ``param_groups``), so checkpoints
read the same.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch


class Adam:
    """``step()`` applies one update from the parameters' ``.grad``; ``params``: tensors with requires_grad."""

    def __init__(self, params: Iterable[torch.Tensor], lr: float = 1e-3, betas: tuple[float, float] = (0.9, 0.999),
                 eps: float = 1e-8):
        self.params = list(params)
        self.lr, self.betas, self.eps = float(lr), (float(betas[0]), float(betas[1])), float(eps)
        self.state: dict[int, dict] = {}

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter with a gradient, in multi-tensor operations (on the CPU each is the
        per-tensor operation applied in turn: the same bits as one loop per parameter, less Python)."""
        beta1, beta2 = self.betas
        live = [(i, p) for i, p in enumerate(self.params) if p.grad is not None]
        if not live:
            return
        for i, p in live:
            if i not in self.state:
                self.state[i] = {"step": torch.tensor(0.0), "exp_avg": torch.zeros_like(p),
                                 "exp_avg_sq": torch.zeros_like(p)}
        states = [self.state[i] for i, _ in live]
        params, grads = [p for _, p in live], [p.grad for _, p in live]
        means, squares = [s["exp_avg"] for s in states], [s["exp_avg_sq"] for s in states]
        counts = [s["step"] for s in states]
        torch._foreach_add_(counts, 1.0)
        ts = [float(t) for t in counts]
        torch._foreach_lerp_(means, grads, 1.0 - beta1)
        torch._foreach_mul_(squares, beta2)
        torch._foreach_addcmul_(squares, grads, grads, value=1.0 - beta2)
        denom = torch._foreach_sqrt(squares)
        torch._foreach_div_(denom, [(1.0 - beta2 ** t) ** 0.5 for t in ts])
        torch._foreach_add_(denom, self.eps)
        torch._foreach_addcdiv_(params, means, denom, [-self.lr / (1.0 - beta1 ** t) for t in ts])

    def state_dict(self) -> dict:
        return {"state": self.state, "param_groups": [{"lr": self.lr, "betas": list(self.betas), "eps": self.eps,
                                                       "params": list(range(len(self.params)))}]}

    def load_state_dict(self, state_dict: dict) -> None:
        group = state_dict["param_groups"][0]
        self.lr, self.betas, self.eps = float(group["lr"]), tuple(map(float, group["betas"])), float(group["eps"])
        self.state = {int(i): {key: value.clone() if torch.is_tensor(value) else torch.tensor(float(value))
                               for key, value in s.items()} for i, s in state_dict["state"].items()}
