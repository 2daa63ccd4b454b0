"""Fuzzing every file reader with hypothesis: any mutation of a good file (bytes flipped or cut, a JSON
or TOML value replaced or deleted, arrays of another shape or type) ends in a correct load or in our
ManifoldgenError, never another exception. Derandomised and bounded (max_examples), so CI runs it in
seconds and always the same examples; ``MANIFOLDGEN_FUZZ=N`` runs N examples per reader instead."""

from __future__ import annotations

import copy
import json
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from manifoldgen import collision
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import save_npz
from manifoldgen.models import CVAE, load_model
from manifoldgen.models.base import document_checksum
from manifoldgen.scene import get_scene
from manifoldgen.tasks import BUILTIN_DIR, load_task_file, task_from_meta
from manifoldgen.viewer.source import read_source

EXAMPLES = int(os.environ.get("MANIFOLDGEN_FUZZ", "0")) or None
FUZZ = settings(max_examples=EXAMPLES or 40, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])
SLOW_FUZZ = settings(FUZZ, max_examples=EXAMPLES or 15)  # readers that build a robot per example

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=6)


def _paths(doc, prefix=()):
    """Every key path into a JSON document."""
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    for key, value in items:
        yield (*prefix, key)
        yield from _paths(value, (*prefix, key))


def mutate_json(data, doc):
    """``doc`` with one value replaced by random JSON, or deleted."""
    doc = copy.deepcopy(doc)
    path = data.draw(st.sampled_from(list(_paths(doc))))
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    if data.draw(st.booleans()):
        parent[path[-1]] = data.draw(json_values)
    elif isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent.pop(path[-1])
    return doc


def mutate_bytes(data, blob: bytes) -> bytes:
    """``blob`` cut short, or with a few bytes overwritten."""
    if data.draw(st.booleans()):
        return blob[:data.draw(st.integers(0, len(blob) - 1))]
    out = bytearray(blob)
    for _ in range(data.draw(st.integers(1, 4))):
        out[data.draw(st.integers(0, len(out) - 1))] = data.draw(st.integers(0, 255))
    return bytes(out)


def _ours_or_loaded(read):
    """Run a reader: a load or a ManifoldgenError are the only acceptable outcomes."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            read()
        except ManifoldgenError as exc:
            assert "\n" not in str(exc)


@pytest.fixture(scope="module")
def good(tmp_path_factory, panda_task, planned_path):
    root = tmp_path_factory.mktemp("good")
    data = collect(panda_task, 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    CVAE(hidden=[8], batch=8).fit(data, epochs=1, seed=0, progress=False, out=root / "model")
    shutil.copy(planned_path("wall"), root / "path.npz")
    return {"root": root, "data": data}


def _npz_case(data, arrays: dict, meta: dict, work: Path) -> Path:
    """A structurally mutated .npz: its meta mutated, or one array replaced by a random one."""
    if data.draw(st.booleans()):
        meta = mutate_json(data, meta)
    else:
        name = data.draw(st.sampled_from(sorted(arrays)))
        arrays = {**arrays, name: data.draw(hnp.arrays(
            st.sampled_from([np.float64, np.float32, np.int64, np.bool_, np.dtype("U3")]),
            hnp.array_shapes(min_dims=0, max_dims=3, max_side=8)))}
    path = work / "m.npz"
    save_npz(path, meta, **arrays)
    return path


@FUZZ
@given(data=st.data())
def test_dataset_reader(good, data, tmp_path_factory):
    work = tmp_path_factory.mktemp("d")
    d = good["data"]
    if data.draw(st.booleans()):
        path = work / "m.npz"
        path.write_bytes(mutate_bytes(data, (good["root"] / "data.npz").read_bytes()))
    else:
        path = _npz_case(data, {"q": d.q, "y": d.y}, d.meta, work)
    _ours_or_loaded(lambda: task_from_meta(Dataset.load(path).meta) if data.draw(st.booleans()) else Dataset.load(path))


@FUZZ
@given(data=st.data())
def test_model_directory_reader(good, data, tmp_path_factory):
    work = tmp_path_factory.mktemp("m") / "model"
    shutil.copytree(good["root"] / "model", work)
    doc = json.loads((work / "model.json").read_text())
    what = data.draw(st.sampled_from(["json", "json-resigned", "text", "weights-resigned"]))
    if what.startswith("json"):
        doc = mutate_json(data, doc)
        if what == "json-resigned" and isinstance(doc, dict):  # past the checksum: the field checks must hold
            doc["sha256"] = document_checksum(doc)
        (work / "model.json").write_text(json.dumps(doc))
    elif what == "text":
        (work / "model.json").write_bytes(mutate_bytes(data, (work / "model.json").read_bytes()))
    else:
        import hashlib
        blob = mutate_bytes(data, (work / "model.safetensors").read_bytes())
        (work / "model.safetensors").write_bytes(blob)
        doc["weights_sha256"] = hashlib.sha256(blob).hexdigest()
        doc["sha256"] = document_checksum(doc)
        (work / "model.json").write_text(json.dumps(doc))

    def read():
        model = load_model(work)
        model.sample([0.4], 3)
    _ours_or_loaded(read)


@SLOW_FUZZ
@given(data=st.data())
def test_scene_reader(panda_task, data, tmp_path_factory):
    doc = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    path = tmp_path_factory.mktemp("s") / "scene.json"
    if data.draw(st.booleans()):
        path.write_text(json.dumps(mutate_json(data, doc)))
    else:
        path.write_bytes(mutate_bytes(data, json.dumps(doc).encode()))
    _ours_or_loaded(lambda: get_scene(panda_task, str(path)).checker(panda_task.robot))


@SLOW_FUZZ
@given(data=st.data())
def test_task_file_reader(data, tmp_path_factory):
    work = tmp_path_factory.mktemp("t")
    shutil.copytree(BUILTIN_DIR / "scenes", work / "scenes")
    text = (BUILTIN_DIR / "pose-panda.toml").read_text()
    lines = text.splitlines()
    how = data.draw(st.sampled_from(["bytes", "drop-line", "value"]))
    if how == "bytes":
        (work / "task.toml").write_bytes(mutate_bytes(data, text.encode()))
    else:
        i = data.draw(st.sampled_from([k for k, line in enumerate(lines) if "=" in line]))
        if how == "drop-line":
            lines.pop(i)
        else:
            key = lines[i].split("=")[0]
            lines[i] = f"{key}= {json.dumps(data.draw(json_values))}"
        (work / "task.toml").write_text("\n".join(lines))
    _ours_or_loaded(lambda: load_task_file(work / "task.toml"))


@SLOW_FUZZ
@given(data=st.data())
def test_path_file_reader(good, data, tmp_path_factory):
    from manifoldgen.io import load_npz
    work = tmp_path_factory.mktemp("p")
    if data.draw(st.booleans()):
        path = work / "m.npz"
        path.write_bytes(mutate_bytes(data, (good["root"] / "path.npz").read_bytes()))
    else:
        meta, arrays = load_npz(good["root"] / "path.npz", ("path",))
        path = _npz_case(data, arrays, meta, work)
    _ours_or_loaded(lambda: read_source(path))


@FUZZ
@given(data=st.data())
def test_collision_cache_reader(panda_task, data, tmp_path_factory):
    candidates = [(a, b) for a in range(4) for b in range(a + 1, 8)]
    kept = [list(p) for p in candidates[::3]]
    stamp = {"robot_sha256": "r", "candidates_sha256": "c", "samples": 30}
    doc = {"robot": "panda", **stamp, "pairs": kept, "pairs_sha256": collision._digest(kept)}
    path = tmp_path_factory.mktemp("c") / "cache.json"
    if data.draw(st.booleans()):
        mutated = mutate_json(data, doc)
        if data.draw(st.booleans()) and isinstance(mutated.get("pairs"), list):  # re-signed: the entries are checked
            mutated["pairs_sha256"] = collision._digest(mutated["pairs"])
        path.write_text(json.dumps(mutated))
    else:
        path.write_bytes(mutate_bytes(data, json.dumps(doc).encode()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pairs = collision.read_matrix_cache(path, stamp, candidates)
    assert pairs is None or set(pairs) <= set(candidates)
