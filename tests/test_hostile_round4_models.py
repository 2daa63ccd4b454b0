"""Model directories whose resealed model.json no longer describes the model (a decoder entry that does not fit its
weights, an unknown key in a sub-object, NaN weights, a copy of the joint limits or of the trained condition range
that its task or data contradict), and the Python API's samplers and arguments under hostile input. Every command
and the API refuse each alike, in one line, with no input changed; genuine models still load."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import manifoldgen as mg
from manifoldgen.data import collect
from manifoldgen.models import CVAE, ConditionalFlowMatching, load_model, open_model, pretrained_model_dir
from manifoldgen.models.files import read_model_dir
from manifoldgen.sampling import MAX_SAMPLES
from refusals import api, cli, refused_as_told, reseal

TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}


def _nan(arrays) -> None:
    arrays["decoder.0.weight"][:] = np.nan


def _widen_limits(doc) -> None:
    d = doc["dims"]["d"]
    doc["normalisation"].update(lower=[-10.0] * d, upper=[10.0] * d)


EDITS = {
    "layers-5": {"edit": lambda d: d["decoder"].update(layers=5)},
    "layers-1": {"edit": lambda d: d["decoder"].update(layers=1)},
    "noise-5": {"edit": lambda d: d["decoder"].update(noise=5)},
    "dims-extra": {"edit": lambda d: d["dims"].update(x=1)},
    "norm-typo": {"edit": lambda d: d["normalisation"].update(q_men=[0.0])},
    "decoder-typo": {"edit": lambda d: d["decoder"].update(lyers=2)},
    "prior-layers-4": {"edit": lambda d: d["decoder"]["prior"].update(layers=4)},
    "prior-typo": {"edit": lambda d: d["decoder"]["prior"].update(stps=2)},
    "prior-names-decoder": {"edit": lambda d: d["decoder"]["prior"].update(net="decoder")},
    "prior-dropped": {"edit": lambda d: d["decoder"].pop("prior")},
    "schedule-linear": {"edit": lambda d: d["config"].update(lr_schedule="linear")},
    "weights-nan": {"weights": _nan},
    "limits-wide": {"edit": _widen_limits},
    "yrange-wide": {"edit": lambda d: d["normalisation"].update(y_low=[-100.0], y_high=[100.0])},
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, panda_task, planned_path):
    """A folder made once: a dataset, a tiny CVAE, its resealed edited copies (:data:`EDITS`) and a planned path."""
    root = tmp_path_factory.mktemp("inputs")
    data = collect(panda_task, 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    for name, change in EDITS.items():
        shutil.copytree(root / "model", root / name)
        reseal(root / name, **change)
    shutil.copy(planned_path("wall"), root / "path.npz")
    return root


def _sample(name: str, condition: str = "0.4") -> str:
    return f"sample {{I}}/{name} --condition {condition} -n 5 -o {{O}}/s.npz"


def _plan(name: str) -> str:
    return f"plan pose --scene wall --time 2 --no-picture --sampler cvae:{{I}}/{name} -o {{O}}/p.npz"


def _wall_sampler(model="project"):
    task = mg.load_task("pose")
    return task, mg.sampler(task, mg.load_scene(task, "wall"), model, seed=0)


CASES = [
    # a decoder entry that does not fit its weights: sample (torch) and plan (the core) refuse alike
    cli("sample-decoder-layers-5", _sample("layers-5"), "its 'decoder' entry does not fit its weights (the weights "
        "lack 'decoder.4.weight', which its 5 layer(s) name)"),
    cli("plan-decoder-layers-5", _plan("layers-5"), "the weights lack 'decoder.4.weight'"),
    cli("sample-decoder-layers-1", _sample("layers-1"), "the weights hold 'decoder.2.bias' besides the 1 layer(s)"),
    api("open-decoder-noise-5", lambda I, O: open_model(I / "noise-5"),
        "'decoder.0' has weight [8, 4] and bias [8], where [8, 6] and [8] fit"),
    # the learned prior's entry: layers its weights lack, an unknown key, the decoder's own network
    cli("plan-prior-layers-4", _plan("prior-layers-4"), "the weights lack 'prior.6.weight', which its 4 layer(s) name"),
    api("load-prior-typo", lambda I, O: load_model(I / "prior-typo"),
        "unknown key 'stps' in 'decoder.prior' (did you mean 'steps'?)"),
    cli("sample-prior-names-decoder", _sample("prior-names-decoder"),
        "'decoder.prior' must name the prior's velocity field 'net' (not the decoder's)"),
    cli("plan-prior-dropped", _plan("prior-dropped"),
        "gives config prior_steps = 4, but its 'decoder' entry names no prior"),
    # a hyper-parameter that is a name, with a name no model knows
    cli("sample-schedule-linear", _sample("schedule-linear"), "config \"lr_schedule\" is \"linear\", not one of "
        "constant, cosine"),
    # unknown keys in model.json's objects
    cli("sample-dims-unknown-key", _sample("dims-extra"), "unknown key 'x' in 'dims'"),
    cli("sample-normalisation-typo", _sample("norm-typo"),
        "unknown key 'q_men' in 'normalisation' (did you mean 'q_mean'?)"),
    api("load-decoder-typo", lambda I, O: load_model(I / "decoder-typo"),
        "unknown key 'lyers' in 'decoder' (did you mean 'layers'?)"),
    # non-finite weights
    cli("sample-weights-nan", _sample("weights-nan"), "tensor 'decoder.0.weight' holds NaN or infinite values"),
    cli("plan-weights-nan", _plan("weights-nan"), "tensor 'decoder.0.weight' holds NaN or infinite values"),
    # copies that the task or the data contradict
    cli("sample-limits-wide", _sample("limits-wide"),
        "its normalisation 'lower' gives panda_joint1 -10, but the robot's limit is -2.8973 (6 more joint(s) differ)"),
    cli("plan-limits-wide", _plan("limits-wide"), "its normalisation 'lower' gives panda_joint1 -10"),
    api("sampler-limits-wide", lambda I, O: _wall_sampler(load_model(I / "limits-wide")),
        "the model: its normalisation 'lower'"),
    cli("sample-yrange-strict", _sample("yrange-wide", "5 --strict"),
        "normalisation y_low/y_high give panda_hand_tcp.z the range [-100, 100], beyond the values its data had "
        "([0.2, 0.7]"),
    # the API: a bounded sample_many, output suffixes, flags, a sampler of another scene, shipped model names
    api("sample-many-huge", lambda I, O: _wall_sampler()[1].sample_many(10 ** 12),
        f"the number of samples must be a whole number from 0 to {MAX_SAMPLES:,}, got 1000000000000"),
    api("raw-many-huge", lambda I, O: _wall_sampler("uniform")[1].raw_many(MAX_SAMPLES + 1), "from 0 to 1,000,000"),
    api("collect-out-txt", lambda I, O: mg.collect("pose", per_condition=3, out=O / "x.txt"),
        "collect: out must end in .npz, got"),
    api("collect-progress-text", lambda I, O: mg.collect("pose", per_condition=3, progress="yes"),
        "collect: progress must be True or False, got str 'yes'"),
    api("train-progress-number", lambda I, O: mg.train(I / "data.npz", "cvae", progress=1, epochs=1),
        "train: progress must be True or False, got int 1"),
    api("query-result-save-txt", lambda I, O: mg.QueryResult.load(I / "path.npz").save(O / "p.txt"),
        "QueryResult.save: file must end in .npz"),
    api("plan-sampler-of-another-scene", lambda I, O: mg.plan("pose", "maze", sampler=_wall_sampler()[1]),
        "plan: the sampler was made for scene 'wall', whose obstacles or held object are not those of scene 'maze'"),
    api("pretrained-relative-path", lambda I, O: mg.pretrained_model_dir("../pretrained/panda-pose-cvae"),
        "no pretrained model '../pretrained/panda-pose-cvae' (a shipped model's plain name, not a path)"),
    api("pretrained-absolute-path", lambda I, O: mg.pretrained_model_dir(str(I / "model")), "plain name, not a path"),
]


def test_the_table_has_unique_ids():
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile_round4_model_input(case, inputs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    refused_as_told(case, inputs, out)


def test_genuine_models_pass_every_check(inputs, tmp_path, panda_task):
    """The shipped CVAE, a fresh CVAE and a flow-matching model (a velocity field) load and make samplers; the
    trained range of a model whose data lies beyond its task's values (read from the dataset's coverage) is kept."""
    data = collect(panda_task, 12, seed=0, conditions=[[0.4], [0.75]], progress=False)
    CVAE(**TINY).fit(data, seed=0, progress=False, out=tmp_path / "beyond")
    ConditionalFlowMatching(hidden=[8], steps=2, batch=8, epochs=1).fit(data, seed=0, progress=False,
                                                                       out=tmp_path / "cfm")
    for folder in (pretrained_model_dir(), inputs / "model", tmp_path / "beyond", tmp_path / "cfm"):
        assert open_model(folder).d == load_model(folder).d == 7
        assert _wall_sampler(load_model(folder))[1].sample_many(2).shape == (2, 7)
    assert read_model_dir(tmp_path / "cfm")[0]["decoder"]["steps"] == 2
    assert read_model_dir(inputs / "model")[0]["decoder"]["prior"] == {"net": "prior", "steps": 4, "layers": 3}
    assert "prior" not in read_model_dir(pretrained_model_dir())[0]["decoder"]  # written before the prior existed
    assert read_model_dir(tmp_path / "beyond")[0]["normalisation"]["y_high"] == [0.75]


def test_a_sampler_plans_its_own_scene():
    task, made = _wall_sampler()
    assert made.scene[0] == "wall"
    assert mg.plan(task, "wall", sampler=made, time_limit=5).solved
