"""Atomic file writes (figures too), output-path checks, one writer per output, and the JSON ``meta`` carried by every
.npz file."""

from __future__ import annotations

import contextlib
import errno
import functools
import glob
import inspect
import json
import os
import re
import tempfile
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from manifoldgen.errors import ManifoldgenError, not_a_file, short

if TYPE_CHECKING:
    import numpy as np


def _umask() -> int:
    """The process umask: from /proc on Linux, else by setting it and setting it back."""
    try:
        status = Path("/proc/self/status").read_text()
        return int(next(line.split()[1] for line in status.splitlines() if line.startswith("Umask:")), 8)
    except (OSError, StopIteration, IndexError, ValueError):
        mask = os.umask(0o022)
        os.umask(mask)
        return mask


def write_error(path: Path, exc: OSError) -> ManifoldgenError:
    """A one-line error for a failed write to ``path`` (disk full, read-only, not a directory ...)."""
    if exc.errno == errno.ENOSPC or exc.errno == errno.EDQUOT:
        fix = "free some space or write elsewhere"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = "choose a writable location"
    else:
        fix = "check the path"
    return ManifoldgenError(f"cannot write {path}: {exc.strerror or exc}; {fix} (nothing was written)")


def _atomic(path: Path, write) -> None:
    """Write through a temporary file in the same directory and a rename; the file gets the
    permissions an ordinary ``open`` would give it (0o666 less the umask). Temporary files that a
    killed writer left (``.NAME.PID-*.tmp`` of a process that is gone) are removed."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise ManifoldgenError(f"{path} exists and is not a regular file (a folder or a device); write elsewhere")
    new_dirs = [d for d in [path.parent, *path.parent.parents] if not d.exists()]  # deepest first
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}-", suffix=".tmp")
    except OSError as exc:
        _remove_empty(new_dirs)
        raise write_error(path, exc) from None
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
        _remove_orphans(path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        _remove_empty(new_dirs)
        raise write_error(path, exc) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        _remove_empty(new_dirs)
        raise


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders a failed write created (deepest first), where they are still empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


def _remove_orphans(path: Path) -> None:
    """Delete ``.NAME.PID-*.tmp`` files beside ``path`` whose writer process no longer exists."""
    for orphan in path.parent.glob(f".{glob.escape(path.name)}.*-*.tmp"):
        pid = orphan.name[len(path.name) + 2:].split("-")[0]
        if pid.isdigit() and not Path(f"/proc/{pid}").exists() and Path("/proc/self").exists():
            orphan.unlink(missing_ok=True)


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    _atomic(path, lambda f: f.write(text.encode()))


def atomic_write_bytes(path: Path, data: bytes) -> None:
    _atomic(path, lambda f: f.write(data))


def save_figure(fig, path: str | Path) -> None:
    """Write a matplotlib figure as PNG atomically and close it."""
    import io as bytes_io

    import matplotlib.pyplot as plt

    buffer = bytes_io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight", metadata=PNG_METADATA)
    plt.close(fig)
    atomic_write_bytes(Path(path), buffer.getvalue())


GENERATOR = "manifoldgen"
GENERATOR_MARK = f'<meta name="generator" content="{GENERATOR}">'  # in the head of every page view --export writes
PNG_METADATA = {"Software": GENERATOR}  # a text chunk of every picture, before its image data
CSV_HEADER = "time_from_start,"  # how every CSV file manifoldgen writes (a trajectory) begins


NPZ_KINDS = ("path", "roadmap")  # the meta "kind" of an .npz that is not a dataset


def npz_kind(path: Path) -> str | None:
    """What an existing .npz holds when manifoldgen wrote it (its JSON ``meta`` has a ``format_version``): the
    meta's ``kind`` (``path``, ``roadmap``), else ``samples`` (what ``sample`` writes) or ``dataset``; None
    otherwise."""
    import numpy as np
    try:
        with np.load(path, allow_pickle=False) as f:
            meta = json.loads(str(f["meta"]))
    except Exception:  # not an .npz, no meta, a pickle ...: not one of ours
        return None
    if not isinstance(meta, dict) or "format_version" not in meta:
        return None
    return meta["kind"] if meta.get("kind") in NPZ_KINDS else "samples" if "generated_by" in meta else "dataset"


JSON_KINDS = ("trajectory", "physics")  # the top-level "kind" of a .json manifoldgen writes


def json_kind(path: Path) -> str | None:
    """What an existing .json holds when manifoldgen wrote it (its ``generator`` is :data:`GENERATOR`): its
    ``kind`` (:data:`JSON_KINDS`; a trajectory written before files carried one: ``trajectory``); None otherwise."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(doc, dict) or doc.get("generator") != GENERATOR:
        return None
    if doc.get("kind") in JSON_KINDS:
        return doc["kind"]
    return "trajectory" if "points" in doc and "joint_names" in doc else None


def output_kind(path: Path) -> str | None:
    """The kind of manifoldgen file an existing ``path`` holds (:func:`npz_kind`, :func:`json_kind`), or None."""
    suffix = path.suffix.lower()
    return npz_kind(path) if suffix == ".npz" else json_kind(path) if suffix == ".json" else None


def written_by_manifoldgen(path: Path) -> bool:
    """Whether the existing file ``path`` is of a kind manifoldgen writes and was written by it: an .npz holding
    its JSON ``meta`` (:func:`npz_kind`), an .html page carrying :data:`GENERATOR_MARK`, a .png with its
    :data:`PNG_METADATA`, a .json object whose ``generator`` is :data:`GENERATOR`, a .csv beginning with
    :data:`CSV_HEADER`. A file of another kind counts as written by it."""
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return npz_kind(path) is not None
    if suffix == ".json":
        try:
            doc = json.loads(path.read_text())
        except (ValueError, UnicodeDecodeError):
            return False
        return isinstance(doc, dict) and doc.get("generator") == GENERATOR
    with open(path, "rb") as f:
        head = f.read(8192)
    if suffix == ".html":
        return GENERATOR_MARK.encode() in head
    if suffix == ".png":
        return b"Software\x00" + GENERATOR.encode() in head
    if suffix == ".csv":
        return head.startswith(CSV_HEADER.encode())
    return True


def check_own_folder(path: Path, markers: tuple[str, ...], what: str = "-o") -> None:
    """Refuse an output folder ``path`` that holds files but none of ``markers`` (the files the command writes
    first into a folder of its own): its files are someone else's and would be replaced."""
    if not path.is_dir() or any((path / marker).exists() for marker in markers):
        return
    names = sorted(p.name for p in path.iterdir())
    if names:
        more = f" and {len(names) - 3} more" if len(names) > 3 else ""
        raise ManifoldgenError(f"{what} {path} holds files this command did not write ({', '.join(names[:3])}{more}; "
                               f"no {' or '.join(markers)}): give a new or empty folder, or delete them")


def _same(a: Path, b: Path) -> bool:
    return a == b or (a.exists() and b.exists() and os.path.samefile(a, b))


def check_output_path(path: str | Path, inputs: Iterable[str | Path | None] = (), *,
                      directory: bool = False, writes: Iterable[str] = (), what: str = "-o",
                      suffixes: tuple[str, ...] = (), markers: tuple[str, ...] = (), owned: bool = True,
                      kind: str | None = None) -> Path:
    """Refuse an output that cannot be written or would destroy an input or a file manifoldgen did not write;
    returns it as a Path.

    A file output (``directory=False``) must end in one of ``suffixes`` (when given), must not be an existing
    directory, and its directory must exist; an existing file it would replace must be one manifoldgen wrote
    (:func:`written_by_manifoldgen`) unless ``owned`` is False (the command reads and checks that file itself
    before it replaces it, as ``plan --roadmap`` does), and with ``kind`` (an .npz output: ``dataset``, ``path``; a
    .json: ``trajectory``, ``physics``) it must hold that kind (a path never replaces a dataset, a trajectory never a
    physics report). A directory output must not be an existing file, and with
    ``markers`` an existing folder must be empty or hold one of them (:func:`check_own_folder`). The folder written
    into must take a new file. No file written (the output, or for a directory output the names it ``writes``
    inside it) may be one of ``inputs`` or a file of an input folder (a model directory's model.json, say), and a
    directory output may not be an input folder.
    """
    path = Path(path)
    if directory:
        if path.exists() and not path.is_dir():
            raise ManifoldgenError(f"{what} {path} is an existing file, but a folder is meant here; "
                                   "give a folder path")
        if not path.parent.exists():
            raise ManifoldgenError(f"{what}: parent folder {path.parent} does not exist; create it or choose "
                                   "another path")
    else:
        if path.is_dir():
            example = path / f"out{suffixes[0] if suffixes else path.suffix or '.npz'}"
            raise ManifoldgenError(f"{what} {path} is a folder, but a file is meant here; give a file path "
                                   f"such as {example}")
        if path.exists() and not path.is_file():
            raise ManifoldgenError(f"{what} {path} is not a regular file (a device, pipe or socket); give a file path")
        if not path.parent.exists():
            raise ManifoldgenError(f"output directory {path.parent} does not exist; create it or choose "
                                   "another path")
        if suffixes and path.name.lower() in suffixes:
            raise ManifoldgenError(f"{what} {path} is only a suffix, not a file name; give a name such as "
                                   f"out{suffixes[0]}")
        if suffixes and path.suffix.lower() not in suffixes:
            raise ManifoldgenError(f"{what} must end in {' or '.join(suffixes)}, got {path}; give a name such as "
                                   f"{path.with_suffix(suffixes[0]).name}")
    written = [path / name for name in writes] if directory else [path]
    for given in inputs:
        if given is None or not Path(given).exists():
            continue
        source = Path(given)
        if source.is_dir():
            if directory and _same(path, source):
                raise ManifoldgenError(f"{what} {path} is the input folder {given}; choose another output folder")
            protected = [f for f in source.iterdir() if f.is_file()]
        else:
            protected = [source]
        for w in written:
            hit = next((f for f in protected if _same(w, f)), None)
            if hit is not None:
                part = "" if hit == source else f", part of the input folder {given}"
                raise ManifoldgenError(f"{what} {path} would overwrite the input {hit}{part}; choose another output")
    if directory and markers:
        check_own_folder(path, markers, what)
    if owned and not directory and path.is_file() and not written_by_manifoldgen(path):
        raise ManifoldgenError(f"{what} {path} exists and was not written by manifoldgen; give another name, or "
                               "delete it to replace it")
    if kind and not directory and path.is_file() and (found := output_kind(path)) not in (None, kind):
        raise ManifoldgenError(f"{what} {path} holds a {found} file, which this {kind} file would replace; give "
                               "another name, or delete it to replace it")
    _check_writable(path if directory and path.is_dir() else path.parent, path)
    return path


def _check_writable(folder: Path, path: Path) -> None:
    """Refuse (as a failed write would) an output ``path`` whose ``folder`` takes no new file: found before any
    work, not after it."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.{os.getpid()}-", suffix=".tmp")
    except OSError as exc:
        raise write_error(path, exc) from None
    os.close(fd)
    os.unlink(probe)


NAME_LENGTH = 100  # characters a user's name that becomes a file name may have
NAME = re.compile(rf"[A-Za-z0-9_@+=:,-][A-Za-z0-9_.@+=:,-]{{0,{NAME_LENGTH - 1}}}")


def check_name(name: str, what: str, fix: str = "rename it") -> str:
    """Refuse a user's string that becomes part of a file name unless it is a plain name: letters, digits and
    ``_-.@+=:,``, at most 100 characters, no leading ``.`` and no ``..`` (so never a path)."""
    if len(name) > NAME_LENGTH:
        raise ManifoldgenError(f"{what} '{name[:40]}...' is {len(name)} characters long; a name becomes a file name: "
                               f"at most {NAME_LENGTH}; {fix}")
    if not (NAME.fullmatch(name) and ".." not in name):
        raise ManifoldgenError(f"{what} '{name}' is not a plain name (letters, digits and _ - . @ + = : , only; no "
                               f"'/', no '..', no leading '.'): it becomes a file name; {fix}")
    return name


@contextlib.contextmanager
def output_lock(path: str | Path, what: str = "-o"):
    """Hold ``<path>.lock`` while writing the output ``path`` (a file or a folder): one writer per output. The
    lock is an exclusive ``flock`` on that file, which holds the writer's process id; a second writer is
    refused, naming the lock and that process. The kernel drops the lock of a process that is gone, so a lock
    file left by a killed writer is taken over. The file is removed when the writer finishes. A lock path that is a
    symbolic link, or a file that holds anything but a process id (not a lock of ours), is refused untouched."""
    import fcntl

    path = Path(path)
    lock = path.with_name(path.name + ".lock")
    if not lock.parent.is_dir():
        raise ManifoldgenError(f"output directory {lock.parent} does not exist; create it or choose another path")
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise ManifoldgenError(f"{lock}, where {what} {path} keeps its lock, is a symbolic link; remove it "
                                       "(a lock is never written through a link)") from None
            raise write_error(lock, exc) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise ManifoldgenError(f"{what} {path} is being written by process {holder} (lock {lock}); wait for it "
                                   "to finish or choose another output") from None
        try:
            current = os.stat(lock).st_ino
        except FileNotFoundError:
            current = None
        if current == os.fstat(fd).st_ino:
            held = os.pread(fd, 64, 0)
            if held.strip() and not held.strip().isdigit():
                os.close(fd)
                raise ManifoldgenError(f"{lock}, where {what} {path} keeps its lock, is a file manifoldgen did not "
                                       "write; move or delete it")
            break
        os.close(fd)  # its writer finished and removed it between our open and flock: lock the next one
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield lock
    finally:
        lock.unlink(missing_ok=True)  # removed while still held, then released
        os.close(fd)


def locks_output(parameter: str):
    """Decorator: a call holds :func:`output_lock` on its argument ``parameter`` (an output path) unless None."""
    def wrap(function):
        signature = inspect.signature(function)

        @functools.wraps(function)
        def locked(*args, **kwargs):
            out = signature.bind(*args, **kwargs).arguments.get(parameter)
            with output_lock(out) if out is not None else contextlib.nullcontext():
                return function(*args, **kwargs)
        return locked
    return wrap


def _unique_keys(pairs: list) -> dict:
    keys = [k for k, _ in pairs]
    twice = next((k for k in keys if keys.count(k) > 1), None)
    if twice is not None:
        raise ValueError(f"key '{twice}' appears twice in one object (which one counts is ambiguous)")
    return dict(pairs)


def read_toml_file(path: Path, what: str) -> tuple[dict, str]:
    """The TOML document of a user's ``what`` file (a task file, a settings file) at ``path``, and its text (for the
    line numbers of later messages): UTF-8, a leading byte-order mark dropped; a binary file (a dataset given as a
    task file) or bad TOML refused in one line."""
    import tomllib

    data = path.read_bytes()
    if data.startswith(b"PK\x03\x04") or b"\x00" in data[:8192]:
        looks = "a zip archive (an .npz dataset, path or roadmap?)" if data.startswith(b"PK") else "a binary file"
        raise ManifoldgenError(f"{path} is {looks}, not a {what} (TOML text); give a .toml {what}")
    try:
        text = data.decode("utf-8-sig")
        return tomllib.loads(text), text
    except UnicodeDecodeError as exc:
        raise ManifoldgenError(f"{path} is not UTF-8 text (byte {exc.start}); save the {what} as UTF-8") from None
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        hint = "a .json file is not a {what}: give a .toml {what}" if path.suffix.lower() == ".json" else "fix the file"
        raise ManifoldgenError(f"{path}: not valid TOML ({exc}); {hint.format(what=what)}") from None


def read_json(text: str):
    """``text`` parsed as JSON, refusing a key given twice in one object (ValueError, as for bad syntax; too
    deep a nesting: RecursionError)."""
    return json.loads(text, object_pairs_hook=_unique_keys)


def save_npz(file: str | Path, meta: dict, /, **arrays: np.ndarray) -> None:
    """Atomically write ``arrays`` (any names, ``path`` included) and ``meta`` (a JSON string) to an .npz."""
    import numpy as np

    _atomic(Path(file), lambda f: np.savez(f, meta=np.array(json.dumps(meta)), **arrays))


NPZ_ARRAYS = ("meta", "q", "y", "path", "nodes", "edges", "lengths", "joint", "center", "radius", "geometry",
              "unfitted", "solid_volume", "union_volume")  # every array name a file manifoldgen writes holds
MAX_NPZ_BYTES = 8 << 30  # the most an .npz may hold uncompressed (a dataset of MAX_ROWS rows of 50 joints: 4 GB)


def _check_members(path: Path, members: list[zipfile.ZipInfo]) -> None:
    """Refuse, from the archive's directory alone (nothing decompressed), an array no manifoldgen file holds and
    an archive that would take more than MAX_NPZ_BYTES once read."""
    unknown = next((m.filename for m in members if m.filename.removesuffix(".npy") not in NPZ_ARRAYS), None)
    if unknown is not None:
        name = short(unknown.removesuffix(".npy"))
        raise ManifoldgenError(f"{path} is not a manifoldgen file: it holds an array {name}, which none holds (read "
                               "without loading it); give a file manifoldgen wrote")
    size = sum(m.file_size for m in members)
    if size > MAX_NPZ_BYTES:
        raise ManifoldgenError(f"{path} would take {size / 2**30:.1f} GiB once read, over the "
                               f"{MAX_NPZ_BYTES >> 30} GiB any manifoldgen file holds; regenerate it")


def load_npz(path: str | Path, required: tuple[str, ...], what: str = "file") -> tuple[dict, dict[str, np.ndarray]]:
    """Read an .npz written by :func:`save_npz` (a ``what``: "dataset", "path file" ..., for messages); clear errors
    for missing, truncated or foreign files."""
    import numpy as np

    path = Path(path)
    if not path.is_file():
        raise ManifoldgenError(f"{not_a_file(path, what)}; give the {what}'s .npz")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise ValueError("a single .npy array, not an .npz archive")
        with loaded as f:
            _check_members(path, f.zip.infolist())
            arrays = {k: f[k] for k in f.files}
    except ManifoldgenError:
        raise
    except Exception as exc:  # zipfile/np raise many types for damaged files
        if "pickle" in str(exc) and zipfile.is_zipfile(path):
            raise ManifoldgenError(f"{path} holds an object array (a pickle), which is never loaded: it could run "
                                   "code; regenerate the file with manifoldgen") from None
        why = "neither a zip archive nor an .npy array" if "pickle" in str(exc) else \
            f"{type(exc).__name__}: {str(exc).splitlines()[0][:120] if str(exc) else ''}"
        raise ManifoldgenError(f"{path} is not a readable .npz file ({why}); it may be truncated or another "
                               "kind of file: regenerate it") from None
    missing = [k for k in ("meta", *required) if k not in arrays]
    if missing:
        raise ManifoldgenError(f"{path} is not a manifoldgen file: missing {', '.join(missing)}")
    try:
        meta = read_json(str(arrays.pop("meta")))
    except (ValueError, RecursionError) as exc:
        raise ManifoldgenError(f"{path} has a corrupted meta field: {exc}") from None
    if not isinstance(meta, dict):
        raise ManifoldgenError(f"{path} has a corrupted meta field (not a JSON object); regenerate it")
    return meta, arrays
