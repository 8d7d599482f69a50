"""Damage seen: the checksums the store records, checked fast (sizes, small files) when an
artefact is opened and in full by ``aoc verify``.

What is recorded when written:

* ``manifest.json``: the content hash of the arrays, a CRC-32 per array (``arrays``: the
  content row names the changed ones), ``files`` (size + CRC-32 of ``corpus.h5``; SHA-256
  when written before the content hash made the file's own record a damage check only) and
  its own seal (``sha256`` of its other keys);
* ``models/<id>/config.json``: ``files`` (weights.pt, values.npy, metrics.csv), sealed;
* ``models/<id>/beliefs.json``: ``files`` (beliefs.npy), sealed;
* ``models/<id>/index/<index_id>/index.json``: ``files`` (index.faiss, its .json and row
  map), sealed.

:func:`verify_store` recomputes every one of them and the corpus content hash: one row per
file, ``ok`` / ``damaged`` / ``missing`` (``unrecorded``: written by an older aoc, no checksum
to compare with). :func:`cleared_rows` clears what dead writers left (``cleared`` rows).
"""

from __future__ import annotations

import json
from pathlib import Path

from aoc_cli.errors import AocError, call
from aoc_cli.store.atomic import crc32_file, seal_status, sha256_file
from aoc_cli.store.layout import INDEXES, models_dir
from aoc_cli.store.reader import Corpus
from aoc_cli.store.sweep import clear_dead

#: Opening an artefact hashes its recorded files up to this size; larger ones are checked
#: by size only (``aoc verify`` hashes everything).
FAST_HASH_BYTES = 16 << 20


def file_status(path: Path, record: dict | None, full: bool = True) -> tuple[str, str]:
    """(status, detail) of a file against its record ``{"bytes", "sha256"}`` (or
    ``"crc32"``: a corpus.h5)."""
    if not path.is_file():
        return "missing", "recorded but not on disk" if record else "not on disk"
    if not record:
        return "unrecorded", "no checksum recorded (written by an older aoc)"
    size = path.stat().st_size
    if size != record.get("bytes"):
        return "damaged", f"{size} bytes, {record.get('bytes')} recorded"
    if full or size <= FAST_HASH_BYTES:
        if "crc32" in record:
            if crc32_file(path) != record.get("crc32"):
                return "damaged", "CRC-32 differs from the one recorded"
            return "ok", "CRC-32 matches"
        if sha256_file(path) != record.get("sha256"):
            return "damaged", "SHA-256 differs from the one recorded"
        return "ok", "SHA-256 matches"
    return "ok", "size matches (a full verify hashes it)"


def read_json(path: Path, what: str, todo: str) -> dict:
    """A JSON object written by aoc; unreadable, not an object or changed since written
    (its seal) is one AocError naming the file and ``todo``."""
    try:
        meta = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise AocError(f"{what}: {path} is missing; {todo}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        first = str(err).splitlines()[0][:120] if str(err) else type(err).__name__
        raise AocError(f"{what}: {path} is not valid JSON ({first}); {todo}") from None
    if not isinstance(meta, dict):
        raise AocError(f"{what}: {path} is not a JSON object; {todo}")
    if seal_status(meta) is False:
        raise AocError(f"{what}: {path} was changed after it was written (its sha256 does not "
                       f"match); {todo}")
    return meta


def check_files(folder: Path, meta: dict, names, what: str, todo: str) -> None:
    """The fast check when an artefact is opened: each of ``names`` recorded in
    ``meta["files"]`` exists, has its size, and (when small) its SHA-256 or CRC-32."""
    records = meta.get("files") or {}
    for name in names:
        if name not in records:
            continue
        status, detail = file_status(Path(folder) / name, records[name], full=False)
        if status in ("damaged", "missing"):
            raise AocError(f"{what}: {Path(folder) / name} is {status} ({detail}); {todo} "
                           f"(`{call('verify')}` lists every damaged file)")


def _json_row(corpus: str, path: Path, rel: str) -> tuple[dict, dict | None]:
    """The row of a sealed JSON file and its content (None when unreadable)."""
    if not path.is_file():
        return {"corpus": corpus, "file": rel, "status": "missing", "detail": "not on disk"}, \
            None
    try:
        meta = json.loads(path.read_text())
        if not isinstance(meta, dict):
            raise ValueError("not a JSON object")
    except (OSError, UnicodeDecodeError, ValueError) as err:
        first = str(err).splitlines()[0][:100] if str(err) else type(err).__name__
        return {"corpus": corpus, "file": rel, "status": "damaged",
                "detail": f"not valid JSON ({first})"}, None
    sealed = seal_status(meta)
    if sealed is False:
        return {"corpus": corpus, "file": rel, "status": "damaged",
                "detail": "changed since written (sha256 differs)"}, meta
    if sealed is None:
        return {"corpus": corpus, "file": rel, "status": "unrecorded",
                "detail": "no checksum recorded (written by an older aoc)"}, meta
    return {"corpus": corpus, "file": rel, "status": "ok", "detail": "sha256 matches"}, meta


def _recorded_rows(corpus: str, folder: Path, base: str, meta: dict | None) -> list[dict]:
    rows = []
    for name, record in sorted(((meta or {}).get("files") or {}).items()):
        status, detail = file_status(folder / name, record)
        rows.append({"corpus": corpus, "file": f"{base}/{name}", "status": status,
                     "detail": detail})
    return rows


def verify_corpus(store, name: str) -> list[dict]:
    """Rows for every file of corpus ``name``: manifest, corpus.h5 (file CRC-32 and the
    content hash of the arrays), and every model's, beliefs' and index's files."""
    folder = store.path(name)
    rows = []
    row, manifest = _json_row(name, folder / "manifest.json", "manifest.json")
    rows.append(row)
    h5 = folder / "corpus.h5"
    if manifest is not None:
        rows += _recorded_rows(name, folder, ".", manifest)
        rows = [dict(r, file=r["file"].removeprefix("./")) for r in rows]
        if not (manifest.get("files") or {}).get("corpus.h5"):
            status, detail = file_status(h5, None)
            rows.append({"corpus": name, "file": "corpus.h5", "status": status,
                         "detail": detail})
    else:
        status, detail = file_status(h5, None)
        rows.append({"corpus": name, "file": "corpus.h5",
                     "status": "missing" if status == "missing" else "unrecorded",
                     "detail": "cannot be checked: no readable manifest"})
    if manifest is not None and h5.is_file() and row["status"] != "damaged":
        rows.append(_content_row(store, name))
    models = models_dir(folder)
    if models.is_dir():
        for model in sorted(p for p in models.iterdir()
                            if p.is_dir() and not p.name.startswith(".")):
            rows += _model_rows(name, model)
    return rows


def _content_row(store, name: str) -> dict:
    try:
        corpus = Corpus(store.path(name))
        failed = None
        try:
            same = corpus.content_hash() == corpus.hash
        except AocError as err:
            same, failed = False, str(err).split(": ", 1)[-1][:160]
        detail = "the arrays hash to the manifest's content_hash" if same else \
            failed or "the arrays no longer hash to the manifest's content_hash"
        if not same:
            changed = corpus.changed_arrays()
            if changed:
                detail += f"; changed: {', '.join(changed)}"
            elif changed is None:
                detail += " (no checksum per array: written by an older aoc)"
        status = "ok" if same else "damaged"
    except AocError as err:
        status, detail = "damaged", str(err).split(": ", 1)[-1][:160]
    return {"corpus": name, "file": "corpus.h5 (content)", "status": status, "detail": detail}


def _model_rows(corpus: str, model: Path) -> list[dict]:
    base = f"models/{model.name}"
    rows = []
    row, config = _json_row(corpus, model / "config.json", f"{base}/config.json")
    rows.append(row)
    rows += _recorded_rows(corpus, model, base, config)
    if (model / "beliefs.json").is_file() or (model / "beliefs.npy").is_file():
        row, beliefs = _json_row(corpus, model / "beliefs.json", f"{base}/beliefs.json")
        rows.append(row)
        rows += _recorded_rows(corpus, model, base, beliefs)
        if beliefs is not None and not beliefs.get("files"):
            status, detail = file_status(model / "beliefs.npy", None)
            rows.append({"corpus": corpus, "file": f"{base}/beliefs.npy", "status": status,
                         "detail": detail})
    index_root = model / INDEXES
    if index_root.is_dir():
        for index in sorted(p for p in index_root.iterdir()
                            if p.is_dir() and not p.name.startswith(".")):
            ibase = f"{base}/index/{index.name}"
            row, meta = _json_row(corpus, index / "index.json", f"{ibase}/index.json")
            rows.append(row)
            rows += _recorded_rows(corpus, index, ibase, meta)
            if meta is not None and not meta.get("files"):
                status, detail = file_status(index / "index.faiss", None)
                rows.append({"corpus": corpus, "file": f"{ibase}/index.faiss",
                             "status": status, "detail": detail})
    return rows


def corpora_to_verify(store, names: list[str] | None = None) -> list[str]:
    """``names`` checked to be folders of the store; default every corpus, damaged ones too."""
    if not names:
        return sorted(store.names() + store.damaged_names())
    for name in names:
        if not store.path(name).is_dir():
            known = ", ".join(store.names()) or "none"
            raise AocError(f"no corpus {name!r} in store {store.root} (known: {known})")
    return list(names)


def cleared_rows(store) -> list[dict]:
    """Clear what dead writers left in the store (:func:`aoc_cli.store.sweep.clear_dead`) and
    return one ``cleared`` row per removed temporary or lock file."""
    rows = []
    for r in clear_dead(store.root):
        detail = (f"temporary of a dead writer (pid {r['pid']}), removed" if r["what"] ==
                  "temporary" else "lock file of a corpus or model that does not exist, removed")
        rows.append({"corpus": r["corpus"], "file": r["path"], "status": "cleared",
                     "detail": detail})
    return rows


def verify_store(store, names: list[str] | None = None) -> list[dict]:
    """Rows ``{"corpus", "file", "status", "detail"}`` for the corpora ``names`` (default:
    every corpus of the store, damaged folders included)."""
    rows = []
    for name in corpora_to_verify(store, names):
        rows += verify_corpus(store, name)
    return rows
