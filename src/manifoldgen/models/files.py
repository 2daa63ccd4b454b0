"""A model directory read without torch: ``model.json`` (validated, checksummed) and ``model.safetensors``.

``model.json`` describes the network that samples (``decoder``: the weights' name prefix, the noise law and
width, the integration steps of a velocity field, ``layers`` Linear layers with SiLU between them, and where the
noise first passes a learned prior, ``prior``: that velocity field's name, steps and layers), so the
compiled core runs it from the file alone (:meth:`SavedModel.native_decoder`): planning with a trained model
never loads torch. Where the core is absent or the file names no ``decoder``, :meth:`SavedModel.sample` loads
the torch model on first use.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import safetensors.numpy

from manifoldgen.constraints import Condition
from manifoldgen.dataset import check_meta
from manifoldgen.errors import ManifoldgenError, did_you_mean, not_a_file, short
from manifoldgen.io import read_json

MODEL_FORMAT_VERSION = 2  # 2: model.json carries "sha256" over all of its fields
WEIGHTS_FILE, CONFIG_FILE = "model.safetensors", "model.json"
LAWS = ("normal", "uniform")  # the noise a sampling network maps: N(0, I) or U(-1, 1)
DECODER_RANGES = {"noise": (1, 4096), "steps": (0, 1000), "layers": (1, 64)}  # a decoder entry's whole numbers
PRIOR_RANGES = {"steps": (1, 1000), "layers": (1, 64)}  # its prior entry's
NAMED_HYPER = {"lr_schedule": ("constant", "cosine")}  # hyper-parameters that are names, and the names known
DOC_KEYS = ("format_version", "model", "config", "dims", "normalisation", "meta", "refine", "mix", "decoder",
            "blend", "weights_sha256", "sha256")
BLEND_DIR = "blend"  # a blended model's partner: a whole model directory inside its own


def document_checksum(doc: dict) -> str:
    """SHA-256 of ``doc`` without its ``sha256`` field, as canonical JSON (key order and spacing ignored)."""
    body = {k: v for k, v in doc.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def read_model_dir(path: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """Read and validate ``model.json`` and ``model.safetensors`` of a model directory: the document and the
    weights by name (numpy arrays)."""
    path = Path(path)
    if not path.is_dir():
        kind = "a file" if path.is_file() else "a device, pipe or socket"
        why = f"model directory {path} is {kind}, not a directory" if path.exists() else \
            not_a_file(path, "model directory")  # not found, or a link to nowhere or to itself
        raise ManifoldgenError(f"{why}; give a model directory written by `manifoldgen train`")
    for name in (CONFIG_FILE, WEIGHTS_FILE):
        if not (path / name).is_file():
            raise ManifoldgenError(f"{path} is missing {name}; it is not a complete model directory "
                                   "(retrain, or copy both model.json and model.safetensors)")
    try:
        doc = read_json((path / CONFIG_FILE).read_text())
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise ManifoldgenError(f"{path}/{CONFIG_FILE} is not valid JSON ({exc}); restore or retrain it") from None
    _validate_doc(path, doc)
    blob = (path / WEIGHTS_FILE).read_bytes()
    if hashlib.sha256(blob).hexdigest() != doc["weights_sha256"]:
        raise ManifoldgenError(f"{path}/{WEIGHTS_FILE} does not match the checksum in {CONFIG_FILE}; "
                               "one of the files was modified or comes from another model")
    try:
        arrays = safetensors.numpy.load(blob)
    except Exception as exc:  # safetensors raises its own error types for damaged files
        raise ManifoldgenError(f"{path}/{WEIGHTS_FILE} is not a readable safetensors file ({exc})") from exc
    broken = next((name for name, array in arrays.items() if not np.isfinite(array).all()), None)
    if broken is not None:
        raise ManifoldgenError(f"{path}/{WEIGHTS_FILE}: tensor '{broken}' holds NaN or infinite values (its samples "
                               "would be NaN); the file was edited or is damaged: restore or retrain the model")
    _check_networks(path, doc, arrays)
    _check_decoder_fits_weights(path, doc, arrays)
    _check_config_fits_weights(path, doc, arrays)
    return doc, arrays


MODEL_NETS = {"cvae": ("decoder", "encoder", "prior"), "cfm": ("velocity",), "cgan": ("critic", "generator"),
              "wgan": ("critic", "generator"), "flow": ("flow",)}  # the networks each built-in model saves


def _check_networks(path: Path, doc: dict, weights: dict[str, np.ndarray]) -> None:
    """Refuse a tensor that belongs to none of a built-in model's networks (:data:`MODEL_NETS`), as torch would
    when it builds the model, for readers that never build it (``plan``'s)."""
    nets = MODEL_NETS.get(doc["model"])
    stray = next((name for name in sorted(weights) if name.split(".")[0] not in nets), None) if nets else None
    if stray is not None:
        raise ManifoldgenError(f"{path}/{WEIGHTS_FILE} holds tensor {short(stray)}, which no network of a "
                               f"'{doc['model']}' model ({', '.join(nets)}) has; the files were edited (the checksum "
                               "is not a signature): restore or retrain the model")


def _net_misfit(net: str, layers: int, inputs: int, outputs: int, weights: dict[str, np.ndarray]) -> str | None:
    """How the weights of network ``net`` differ from ``layers`` Linear layers chaining ``inputs`` to ``outputs``
    values: a named weight missing or of the wrong shape, or a weight it does not name; None where they fit."""
    named = [f"{net}.{2 * i}.{part}" for i in range(layers) for part in ("weight", "bias")]
    missing = next((name for name in named if name not in weights), None)
    if missing is not None:
        return f"the weights lack '{missing}', which its {layers} layer(s) name"
    extra = next((name for name in sorted(weights) if name.startswith(f"{net}.") and name not in named), None)
    if extra is not None:
        return f"the weights hold '{extra}' besides the {layers} layer(s) it names"
    width = inputs
    for i in range(layers):
        weight, bias = weights[f"{net}.{2 * i}.weight"], weights[f"{net}.{2 * i}.bias"]
        out = outputs if i == layers - 1 else (weight.shape[0] if weight.ndim == 2 else -1)
        if weight.shape != (out, width) or bias.shape != (out,):
            return (f"'{net}.{2 * i}' has weight {list(weight.shape)} and bias {list(bias.shape)}, where "
                    f"{[out, width]} and {[out]} fit")
        width = out
    return None


def _decoder_misfit(decoder: dict, dims: dict, weights: dict[str, np.ndarray]) -> str | None:
    """How the sampling network's weights differ from what ``decoder`` (a validated model.json entry) says: a named
    weight missing or of the wrong shape, a weight it does not name, widths that do not chain from its inputs
    (noise and condition; state, condition and time for a velocity field) to ``d`` outputs, or a prior's from
    noise, condition and time to noise; None where they fit."""
    if decoder["steps"] and decoder["noise"] != dims["d"]:
        return f"a velocity field's noise is a state of {dims['d']} values, not {decoder['noise']}"
    width = dims["d"] + dims["k"] + 1 if decoder["steps"] else decoder["noise"] + dims["k"]
    misfit, prior = _net_misfit(decoder["net"], decoder["layers"], width, dims["d"], weights), decoder.get("prior")
    if misfit is None and prior is not None:
        inputs = decoder["noise"] + dims["k"] + 1
        misfit = _net_misfit(prior["net"], prior["layers"], inputs, decoder["noise"], weights)
    return misfit


def _check_decoder_fits_weights(path: Path, doc: dict, weights: dict[str, np.ndarray]) -> None:
    """Refuse a ``decoder`` entry that does not describe its weights (:func:`_decoder_misfit`), so that every
    command (torch or the compiled core) refuses the model alike."""
    misfit = _decoder_misfit(doc["decoder"], doc["dims"], weights) if doc.get("decoder") else None
    if misfit is not None:
        raise ManifoldgenError(f"{path}/{CONFIG_FILE}: its 'decoder' entry does not fit its weights ({misfit}); the "
                               "files come from different models or were edited (the checksum is not a signature): "
                               "restore or retrain the model")


def _check_config_fits_weights(path: Path, doc: dict, weights: dict[str, np.ndarray]) -> None:
    """Refuse a ``config`` whose sampling network's sizes (``hidden`` widths, ``latent``) differ from the weights the
    ``decoder`` entry names, or whose ``prior_steps`` differ from its prior's: the file was edited and resealed (its
    checksum is not a signature), and what it says about the model would mislead whoever reads it."""
    decoder, config = doc.get("decoder"), doc["config"]
    if not decoder:
        return
    shapes = [weights[f"{decoder['net']}.{2 * i}.weight"] for i in range(decoder["layers"])]
    claims = {"hidden": (config.get("hidden"), [int(w.shape[0]) for w in shapes[:-1]])}
    if not decoder["steps"]:  # a sampling network fed noise and the condition
        claims["latent"] = (config.get("latent"), int(shapes[0].shape[1]) - doc["dims"]["k"])
    for key, (said, held) in claims.items():
        if said is not None and said != held:
            raise ManifoldgenError(f"{path}/{CONFIG_FILE} gives config {key} = {said}, but its '{decoder['net']}' "
                                   f"weights have {held}: the file was edited (its checksum is not a signature); "
                                   "restore or retrain the model")
    said, held = config.get("prior_steps"), decoder["prior"]["steps"] if "prior" in decoder else 0
    if said is not None and said != held:  # torch would sample through one prior and the core through another
        raise ManifoldgenError(f"{path}/{CONFIG_FILE} gives config prior_steps = {said}, but its 'decoder' entry "
                               f"{f'integrates its prior in {held} steps' if held else 'names no prior'}: the file was "
                               "edited (its checksum is not a signature); restore or retrain the model")


def _hyper_value(key: str, value) -> bool:
    """Whether ``value`` can be hyper-parameter ``key`` in a model.json: a finite number, a list of positive whole
    numbers (layer widths), or for a key of :data:`NAMED_HYPER` one of its names."""
    if key in NAMED_HYPER:
        return value in NAMED_HYPER[key]
    if isinstance(value, list):
        return all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _validate_doc(path: Path, doc: object) -> None:
    def bad(why: str) -> ManifoldgenError:
        return ManifoldgenError(f"{path}/{CONFIG_FILE}: {why}; the file was edited or is damaged: "
                                "restore it or retrain the model")

    if not isinstance(doc, dict):
        raise bad("not a JSON object")
    if doc.get("format_version") != MODEL_FORMAT_VERSION:
        raise bad(f"format_version {doc.get('format_version')!r} is not supported (expected {MODEL_FORMAT_VERSION}; "
                  "version 1 files carry no checksum of their fields)")
    if doc.get("sha256") != document_checksum(doc):
        raise bad("its contents do not match its checksum 'sha256' (a normalisation, range, architecture or "
                  "other field was changed)")
    _refuse_unknown_keys(doc, DOC_KEYS, "", bad)
    for key, kind in (("model", str), ("config", dict), ("dims", dict),
                      ("normalisation", dict), ("meta", dict), ("weights_sha256", str)):
        if not isinstance(doc.get(key), kind):
            raise bad(f"field '{key}' is missing or not a {kind.__name__}")
    odd = next((key for key, value in doc["config"].items() if not _hyper_value(key, value)), None)
    if odd in NAMED_HYPER:
        raise bad(f"config {short(odd)} is {short(doc['config'][odd])}, not one of {', '.join(NAMED_HYPER[odd])}")
    if odd is not None:  # every other hyper-parameter is a number or a list of layer widths
        raise bad(f"config {short(odd)} is {short(doc['config'][odd])}, not a finite number or a list of widths")
    _refuse_unknown_keys(doc["dims"], ("d", "k"), " in 'dims'", bad)
    d, k = doc["dims"].get("d"), doc["dims"].get("k")
    if not (isinstance(d, int) and isinstance(k, int) and d > 0 and k > 0):
        raise bad("dims must hold positive integers d and k")
    sizes = {"q_mean": d, "q_std": d, "y_mean": k, "y_std": k, "y_low": k, "y_high": k, "lower": d, "upper": d}
    _refuse_unknown_keys(doc["normalisation"], tuple(sizes), " in 'normalisation'", bad)
    for key, size in sizes.items():
        values = doc["normalisation"].get(key)
        if not (isinstance(values, list) and len(values) == size
                and all(isinstance(v, (int, float)) and np.isfinite(v) for v in values)):
            raise bad(f"normalisation '{key}' must be {size} finite numbers")
    norm = doc["normalisation"]
    if min(norm["q_std"] + norm["y_std"]) <= 0:
        raise bad("normalisation standard deviations must be positive")
    if any(lo > hi for lo, hi in zip(norm["lower"] + norm["y_low"], norm["upper"] + norm["y_high"])):
        raise bad("a lower bound (joint limit or condition range) exceeds its upper bound")
    joints = doc["meta"].get("joints")
    if not isinstance(doc["meta"].get("robot"), str) or not isinstance(joints, list) or len(joints) != d:
        raise bad(f"meta must name the robot and its {d} joints")
    check_meta(doc["meta"], k, f"{path}/{CONFIG_FILE}")
    _check_trained_range(norm, doc["meta"], bad)
    blend = doc.get("blend")
    if blend is not None and not (
            isinstance(blend, dict) and set(blend) == {"share", "sha256"} and isinstance(blend["share"], float)
            and 0 < blend["share"] < 1 and isinstance(blend["sha256"], str) and len(blend["sha256"]) == 64):
        raise bad("'blend' must hold the partner's 'share' of the rows (a number in (0, 1)) and the 'sha256' of "
                  f"its {BLEND_DIR}/{CONFIG_FILE}, nothing else")
    decoder = doc.get("decoder")
    if isinstance(decoder, dict):
        _refuse_unknown_keys(decoder, ("net", "law", *DECODER_RANGES, "prior"), " in 'decoder'", bad)
    if decoder is not None and not (
            isinstance(decoder, dict) and isinstance(decoder.get("net"), str) and decoder.get("law") in LAWS
            and all(isinstance(decoder.get(key), int) and not isinstance(decoder.get(key), bool)
                    and low <= decoder[key] <= high for key, (low, high) in DECODER_RANGES.items())):
        raise bad("'decoder' must name the sampling network 'net', its noise 'law' (normal or uniform), "
                  "'noise' width, integration 'steps' and number of Linear 'layers' (whole numbers in "
                  + ", ".join(f"{key} [{low}, {high}]" for key, (low, high) in DECODER_RANGES.items()) + ")")
    prior = decoder.get("prior") if decoder else None
    if isinstance(prior, dict):
        _refuse_unknown_keys(prior, ("net", *PRIOR_RANGES), " in 'decoder.prior'", bad)
    if prior is not None and not (
            isinstance(prior, dict) and isinstance(prior.get("net"), str) and prior["net"] != decoder["net"]
            and all(isinstance(prior.get(key), int) and not isinstance(prior.get(key), bool)
                    and low <= prior[key] <= high for key, (low, high) in PRIOR_RANGES.items())):
        raise bad("'decoder.prior' must name the prior's velocity field 'net' (not the decoder's), its integration "
                  "'steps' and number of Linear 'layers' (whole numbers in "
                  + ", ".join(f"{key} [{low}, {high}]" for key, (low, high) in PRIOR_RANGES.items()) + ")")


def _refuse_unknown_keys(entry: dict, keys: tuple[str, ...], where: str, bad) -> None:
    """Refuse a key of ``entry`` (the document, or its object that ``where`` names: " in 'dims'") that is not one
    of ``keys``, naming the nearest known one."""
    unknown = next((key for key in entry if key not in keys), None)
    if unknown is not None:
        raise bad(f"unknown key '{unknown}'{where}{did_you_mean(unknown, keys)}")


def _check_trained_range(norm: dict, meta: dict, bad) -> None:
    """Refuse a trained condition range (``y_low``, ``y_high``: the training rows' extremes) reaching beyond every
    condition value the data had: its task's values (meta ``condition``) and, where the dataset recorded them, the
    values it was collected at (the keys of meta ``coverage.modes``). A wider range would let ``--strict`` pass
    conditions the model never saw."""
    values = list(meta.get("condition", {}).get("values", []))
    modes = meta.get("coverage", {}).get("modes") if isinstance(meta.get("coverage"), dict) else None
    for key in modes if isinstance(modes, dict) else ():
        try:
            row = json.loads(key)
        except ValueError:
            continue
        if isinstance(row, list) and len(row) == len(norm["y_low"]) and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in row):
            values.append(row)
    if not values:
        return
    low, high = np.min(values, axis=0), np.max(values, axis=0)
    slack = 1e-6 * (1.0 + np.abs(low) + np.abs(high))  # the rows' values as float32 round them
    beyond = np.flatnonzero((np.asarray(norm["y_low"]) < low - slack) | (np.asarray(norm["y_high"]) > high + slack))
    if len(beyond):
        i = int(beyond[0])
        name = (meta.get("condition", {}).get("names") or [f"y{j}" for j in range(len(low))])[i]
        raise bad(f"normalisation y_low/y_high give {name} the range [{norm['y_low'][i]:g}, "
                  f"{norm['y_high'][i]:g}], beyond the values its data had ([{low[i]:g}, {high[i]:g}] by meta "
                  "'condition' and 'coverage')")


def check_mix_refine(path: str | Path, doc: dict) -> tuple[int | None, float | None]:
    """The document's ``refine`` (projection iterations, 0-1000) and ``mix`` (a share in [0, 1]), each or None."""
    refine, mix = doc.get("refine"), doc.get("mix")
    if refine is not None and (isinstance(refine, bool) or not isinstance(refine, int) or not 0 <= refine <= 1000):
        raise ManifoldgenError(f"{path}/{CONFIG_FILE} has an invalid refine {refine!r}; retrain or restore it")
    if mix is not None and (isinstance(mix, bool) or not isinstance(mix, (int, float)) or not 0 <= mix <= 1):
        raise ManifoldgenError(f"{path}/{CONFIG_FILE} has an invalid mix {mix!r} (a share in [0, 1]); retrain "
                               "or restore it")
    return refine, mix


def read_blend(path: str | Path, doc: dict, read: Callable[[Path], object]) -> tuple[object, float] | None:
    """A blended model's partner (``read(path / BLEND_DIR)``) and its share of the rows, or None without a ``blend``
    entry; refused unless the partner's model.json is the one the entry names (its ``sha256``), blends nothing
    itself, and models the same robot, joints and condition width."""
    entry = doc.get("blend")
    if entry is None:
        return None
    folder = Path(path) / BLEND_DIR
    fix = "the files were edited or copied in part: copy the whole model directory, or retrain it"
    try:
        said = read_json((folder / CONFIG_FILE).read_text())
    except (OSError, ValueError, UnicodeDecodeError, RecursionError):
        raise ManifoldgenError(f"{path}/{CONFIG_FILE} blends in the model in {folder}, whose {CONFIG_FILE} is missing "
                               f"or unreadable; {fix}") from None
    if not isinstance(said, dict) or said.get("sha256") != entry["sha256"]:
        raise ManifoldgenError(f"{folder}/{CONFIG_FILE} is not the partner {path}/{CONFIG_FILE} names (its sha256 "
                               f"differs); {fix}")
    if "blend" in said:
        raise ManifoldgenError(f"{folder} blends in a model itself; a blend has one partner: retrain the model")
    partner = read(folder)
    if (partner.d, partner.k) != (doc["dims"]["d"], doc["dims"]["k"]) or any(
            partner.meta.get(key) != doc["meta"].get(key) for key in ("robot", "joints")):
        raise ManifoldgenError(f"{folder} models another robot, joints or condition than {path}; {fix}")
    return partner, entry["share"]


class BlendDecoder:
    """Two sampling networks in the core as one (``sample(y (k,), count, seed) -> (count, d)``): each row comes
    from ``partner`` with probability ``share``, else from ``own``, in an order the seed shuffles."""

    def __init__(self, own, partner, share: float):
        self.own, self.partner, self.share = own, partner, share

    def sample(self, y: np.ndarray, count: int, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        taken = int(rng.binomial(count, self.share))
        rows = np.concatenate([self.own.sample(y, count - taken, int(rng.integers(0, 2**63 - 1))),
                               self.partner.sample(y, taken, int(rng.integers(0, 2**63 - 1)))])
        return rows[rng.permutation(count)]


def blend_decoder(own, blend: tuple[object, float] | None):
    """``own`` (a core decoder or None) with the ``blend`` partner's (:class:`BlendDecoder`); None where either has
    none (torch then samples both)."""
    if blend is None or own is None:
        return own
    partner = blend[0].native_decoder()
    return BlendDecoder(own, partner, blend[1]) if partner is not None else None


def blend_row_cost(own: int | None, blend: tuple[object, float] | None) -> int | None:
    """Mean multiply-adds per row of ``own`` (or None) blended with the ``blend`` partner's."""
    if blend is None or own is None:
        return own
    partner = blend[0].row_cost()
    return None if partner is None else round((1 - blend[1]) * own + blend[1] * partner)


def decoder_row_cost(decoder: dict, weights: dict) -> int:
    """Multiply-adds to sample one row with the sampling network ``decoder`` (a model.json ``decoder`` entry) and
    its ``weights`` by name (as :func:`core_decoder` takes them): its Linear weights, twice per integration step
    (Heun) for a velocity field; and its prior's likewise."""
    def macs(net: str, layers: int) -> int:
        return sum(int(np.prod(tuple(weights[f"{net}.{2 * i}.weight"].shape))) for i in range(layers))

    prior = decoder.get("prior")
    return (macs(decoder["net"], decoder["layers"]) * max(1, 2 * int(decoder["steps"]))
            + (macs(prior["net"], prior["layers"]) * 2 * int(prior["steps"]) if prior else 0))


def core_decoder(decoder: dict, weights: dict[str, np.ndarray], d: int, norm: dict):
    """``manifoldgen_core.Decoder`` for the sampling network ``decoder`` (a model.json ``decoder`` entry) with
    ``weights`` by name (``NET.2i.weight (out, in)``, ``NET.2i.bias (out,)``), or None without the core."""
    from manifoldgen.core_extension import core_module

    core = core_module()
    if core is None:
        return None
    def layers(net: str, count: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        names = [f"{net}.{2 * i}" for i in range(count)]
        return ([np.ascontiguousarray(weights[f"{name}.weight"], dtype=np.float32) for name in names],
                [np.ascontiguousarray(weights[f"{name}.bias"], dtype=np.float32) for name in names])

    prior = decoder.get("prior")
    pw, pb = layers(prior["net"], prior["layers"]) if prior else ([], [])
    try:
        return core.Decoder(*layers(decoder["net"], decoder["layers"]), d if decoder["steps"] else decoder["noise"],
                            decoder["law"] == "uniform",
                            *(np.asarray(norm[key], float) for key in ("q_mean", "q_std", "y_mean", "y_std",
                                                                       "lower", "upper")), steps=decoder["steps"],
                            prior_weights=pw, prior_biases=pb, prior_steps=prior["steps"] if prior else 0)
    except (ValueError, TypeError, RuntimeError) as exc:  # the entry's sizes or steps do not fit the weights
        why = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        raise ManifoldgenError(f"the model's 'decoder' entry does not fit its weights ({why}); the files come from "
                               "different models or were edited: retrain or restore them") from None


class ModelFacts:
    """What a trained model's files say besides its weights: ``name``, ``config``, ``meta``, ``norm``, ``d``,
    ``k``, ``refine``, ``mix``, ``blend``, and the conditions it was trained on."""

    name: str
    meta: dict
    norm: dict
    k: int
    blend: tuple | None = None  # a partner model and its share of the rows

    @property
    def label(self) -> str:
        """The model's name, joined by its blend partner's (``cvae+cfm``)."""
        return self.name if self.blend is None else f"{self.name}+{self.blend[0].name}"

    @property
    def condition(self) -> Condition:
        """The conditions the model was trained on: names and units from meta, range from the data."""
        info = self.meta.get("condition", {})
        names = tuple(info.get("names", [f"y{i}" for i in range(self.k)]))
        units = tuple(info.get("units", [""] * self.k))
        return Condition(names, units, np.array([self.norm["y_low"], self.norm["y_high"]], float))

    def check_condition(self, y: np.ndarray, strict: bool = False) -> np.ndarray:
        """y as (B, k); outside the trained range: warn naming the range, or raise when strict."""
        return self.condition.check(y, strict=strict)


class SavedModel(ModelFacts):
    """A model directory as the planners use it: its facts, its network in the core, torch only if needed
    (``load``: path -> the torch model, :func:`manifoldgen.models.load_model`)."""

    def __init__(self, path: str | Path, load: Callable[[Path], object]):
        self.path, self._load = Path(path), load
        doc, self.weights = read_model_dir(self.path)
        self.name, self.config, self.meta, self.norm = doc["model"], doc["config"], doc["meta"], doc["normalisation"]
        self.d, self.k = doc["dims"]["d"], doc["dims"]["k"]
        self.refine, self.mix = check_mix_refine(self.path, doc)
        self.decoder = doc.get("decoder")
        self.blend = read_blend(self.path, doc, lambda folder: SavedModel(folder, load))
        self._torch_model = None

    def native_decoder(self):
        """The sampling network in the compiled core (see :func:`core_decoder`; blended with the partner's), or
        None."""
        own = core_decoder(self.decoder, self.weights, self.d, self.norm) if self.decoder else None
        return blend_decoder(own, self.blend)

    def row_cost(self) -> int | None:
        """Multiply-adds to sample one row (:func:`decoder_row_cost`), or None without a core decoder entry."""
        return blend_row_cost(decoder_row_cost(self.decoder, self.weights) if self.decoder else None, self.blend)

    def sample(self, y: np.ndarray, n: int, generator=None) -> np.ndarray:
        """(n, d) rows at ``y`` from the torch model (loaded on first use): see ``ConditionalSampler.sample``."""
        if self._torch_model is None:
            self._torch_model = self._load(self.path)
        return self._torch_model.sample(y, n, generator)
