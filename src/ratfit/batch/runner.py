"""Batch fitting on Dask distributed: one task per (input, channel, settings), resumable.

A manifest (TOML or JSON, or the same structure as a dict) names the inputs
and the fit settings::

    [defaults]                 # every fit (RationalFitter parameters + segment options)
    dt = 0.05
    max_total = 40

    [[settings]]               # combinations: every input is fitted with each of them
    basis = "legendre"
    [[settings]]
    basis = "chebyshev"

    [[inputs]]
    path = "data/*.dat"        # glob, relative to the manifest's folder
    format = "nist"            # per-entry override (beats defaults and combinations)
    channels = [0]             # 0-based indices or names (default: every channel)

    [[inputs]]
    path = "cornell/*.brdf"    # measured BRDFs: one task per file, as `ratfit brdf fit`
    max_points = 300           # BRDF settings: parametrization, floor_rel, cosine, clamp,
                               # color, max_points, subset_by, positive_q, polish

Every task is one job request (:mod:`ratfit.jobs`): a data file's channel is a
:class:`~ratfit.jobs.FitRequest`, a BRDF file (``kind = "brdf"``; by default a
glob ending in .brdf, .binary, .astm or .exr, or a MERL/Cornell/ASTM/EXR
``format``) one :class:`~ratfit.jobs.BRDFFitRequest` for the channels asked, so a
task's fit is the one the command or the Python job gives for the same settings.

An entry may also be a bare glob string, or carry its own ``settings`` list
(replacing the global combinations). Precedence: built-in defaults < ``defaults``
< combination < entry.

Layout of OUTDIR, one file per finished task, each written atomically::

    <input>.<channel>.<settings id>-<key>.json   verified fit (``ratfit.fitfile``); its
                                                 provenance["batch"] holds the summary row
    .rows/<same name>.json                       row of a task with no verified fit
                                                 ("no-fit") or that raised ("failed")
    summary.csv, summary.parquet                 one row per task, rewritten at the end

``key`` hashes the input, the exact channel name and the settings id: channels whose
names read alike once made file-safe (``a b``, ``a_b``) get different names. A new
OUTDIR is built beside its place and moved there when the batch ends (or is stopped
by Ctrl-C); an error leaves nothing. The client writes every file (workers only
compute), so a worker that dies or a Ctrl-C cannot leave a partial file, and with
``scheduler=`` only the inputs need to be visible to the workers (at the same
absolute paths). Resume: a task whose fit file (or no-fit/failed row) exists for the
same input content and settings is not run again, once its fit file has loaded
(digest, types, no pole; a BRDF file's block too) and, for a data file's channel, its
function met the task's segments on the data again; failed and no-fit tasks run again
only with ``rerun_failed``.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import hashlib
import json
import os
import re
import sys
import time
import tomllib
import traceback
import uuid
import warnings
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ratfit._atomic import atomic_dir, atomic_open, atomic_path
from ratfit._progress import StepProgress
from ratfit.brdf.options import BRDF_SOLVER
from ratfit.core.options import FIT_OPTIONS, SEGMENT_OPTIONS
from ratfit.core.validation import check_bool, check_choice, check_int, check_width
from ratfit.errors import InputError, RatfitError
from ratfit.jobs import BRDFFitRequest, FitRequest

__all__ = [
    "COLUMNS",
    "FIT_PARAMS",
    "BatchInterrupted",
    "BatchSummary",
    "MissingDependency",
    "Task",
    "execute",
    "load_manifest",
    "plan",
    "run",
    "settings_id",
    "write_summary",
]

INSTALL_HINT = 'pip install ".[batch]" (from the ratfit checkout)'
ROWS_DIR = ".rows"
SUMMARY_STEM = "summary"

# Summary columns, in order: what a lab sorts and filters a database of fits by.
COLUMNS: tuple[str, ...] = (
    "input", "channel", "settings_id", "status", "n", "m", "total", "verified",
    "linf", "l2", "max_rel_error", "max_violation", "qp_solves", "seconds",
    "wall_seconds", "message", "fit_file", "settings", "resumed",
)
STATUSES = ("ok", "no-fit", "failed", "pending")


class MissingDependency(RatfitError):
    """dask.distributed or pyarrow is not installed (the ``batch`` extra)."""


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C during a batch: futures cancelled, finished results kept, summary written."""

    def __init__(self, summary: BatchSummary) -> None:
        super().__init__("batch interrupted")
        self.summary = summary


# ---------------------------------------------------------------------------- settings
# Every setting with its built-in default: the fitter's options from the one spec
# (ratfit.core.options), the segment widths, and how an input is read. All but
# ``jobs`` and ``warm_start`` enter the settings id (they change how fast, not what). ``jobs``
# defaults to 1: Dask supplies the parallelism, threads inside each task would
# only oversubscribe the cores.
FIT_PARAMS = tuple(k for k in FIT_OPTIONS if k != "callback")
# What a BRDF file's request takes besides the fit options and widths (the names of
# ratfit.jobs.BRDFFitRequest), with their defaults.
BRDF_SETTINGS: dict[str, Any] = {
    "parametrization": None, "floor_rel": None, "cosine": False, "clamp": None,
    "color": "rgb", "max_points": None, "subset_by": "samples", "positive_q": False,
    "polish": True,
}
KINDS = ("auto", "data", "brdf")
# kind "auto": an entry is a BRDF file by its glob's suffix or its format
BRDF_SUFFIXES = (".brdf", ".binary", ".astm", ".exr")
BRDF_ONLY_FORMATS = ("merl", "cornell", "astm", "exr")
DEFAULTS: dict[str, Any] = {
    **{k: FIT_OPTIONS[k].default for k in FIT_PARAMS}, "jobs": 1,
    **{k: o.default for k, o in SEGMENT_OPTIONS.items()},
    "format": None, "dim": None, "monomial": True, "kind": "auto", **BRDF_SETTINGS,
}
# A BRDF file's settings start from the BRDF fitter's solver, as `ratfit brdf fit`.
BRDF_DEFAULTS: dict[str, Any] = {**DEFAULTS, "solver": BRDF_SOLVER}
_NOT_HASHED = ("jobs", "warm_start")
# Settings added after manifests were in use: left out of the settings id while they
# hold their default, so results of earlier runs keep their ids (and are resumed).
_HASHED_IF_SET = ("formulation", "time_limit", "work_limit", "kind", *BRDF_SETTINGS)
_QUIET_VALUES = {**{k: (DEFAULTS[k],) for k in _HASHED_IF_SET}, "kind": ("auto", "data")}
ENTRY_KEYS = ("path", "channels", "settings")
TOP_KEYS = ("inputs", "defaults", "settings")


def _check_setting(key: str, value: Any, where: str) -> Any:
    """One setting's value, normalised (floats as float), or InputError naming ``where``."""
    if key in FIT_OPTIONS:
        opt = FIT_OPTIONS[key]
        if opt.kind == "choice" and isinstance(value, str):
            value = value.lower()
        if key in ("min_total", "jobs") and value is None:
            raise InputError(f"{where}: {key} must be an integer >= {opt.minimum}, got None")
        return opt.check(value, where)
    if key in SEGMENT_OPTIONS:
        return check_width(value, key, where=where, positive=True, below_one=key == "dt")
    if key == "format":
        from ratfit.brdf.io import BRDF_FORMATS
        from ratfit.io.data import FORMATS

        names = tuple(dict.fromkeys((*FORMATS, *BRDF_FORMATS)))
        if value is None:
            return None
        if not isinstance(value, str):
            raise InputError(f"{where}: format must be one of {', '.join(names)}, "
                             f"got {value!r}")
        return check_choice(value.lower(), "format", names, where=where)
    if key == "kind":
        return check_choice(value, "kind", KINDS, where=where)
    if key in BRDF_SETTINGS:
        return value  # checked with the others when the request is made
    if key == "dim":
        return check_int(value, "dim", minimum=1, where=where, allow_none=True)
    if key == "monomial":
        return check_bool(value, "monomial", where=where)
    raise InputError(f"{where}: unknown key {key!r}")  # pragma: no cover (filtered before)


def _check_table(table: Any, where: str, allowed: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(table, Mapping):
        raise InputError(f"{where}: must be a table of settings, got {type(table).__name__}")
    out: dict[str, Any] = {}
    for key, value in table.items():
        if key not in allowed:
            raise InputError(
                f"{where}: unknown key {key!r}; valid keys: {', '.join(allowed)}"
            )
        if key in DEFAULTS:
            out[key] = _check_setting(key, value, where)
        else:
            out[key] = value
    return out


def _check_combined(settings: dict[str, Any], where: str) -> None:
    """Every setting checked alone and together: the request they make is made."""
    request_of(settings, Path(where), where=where)


def request_of(settings: Mapping[str, Any], path: Path, *,
               where: str | None = None) -> FitRequest | BRDFFitRequest:
    """The job request of one task's settings (kind "data": a data file's fit, with
    ``settings["channels"]`` its channel; kind "brdf": a BRDF file's fit)."""
    fit = {k: settings[k] for k in FIT_PARAMS}
    widths = {"dt": settings["dt"], "abs_width": settings["abs_width"]}
    chans = settings.get("channels") or ()
    if settings["kind"] == "brdf":
        for key in ("dim", "monomial"):
            if settings[key] != DEFAULTS[key]:
                raise InputError(f"{where}: {key} is a setting of data files, not of BRDF files")
        own = {k: settings[k] for k in BRDF_SETTINGS}
        return BRDFFitRequest.from_settings(path, {**fit, **widths, **own, "channels": chans,
                                                   "format": settings["format"]}, where=where)
    for key, default in BRDF_SETTINGS.items():
        if settings[key] != default:
            raise InputError(f"{where}: {key} is a setting of BRDF files (kind = \"brdf\"), "
                             "not of data files")
    return FitRequest.from_settings(path, {**fit, **widths, "channels": chans,
                                           "format": settings["format"], "dim": settings["dim"],
                                           "monomial": settings["monomial"]}, where=where)


def _entry_kind(pattern: str, layers: tuple[Mapping[str, Any], ...]) -> str:
    """An entry's kind: given (the last layer that says wins), else "brdf" for a glob
    ending in a BRDF suffix or a BRDF-only format, else "data"."""
    kind, fmt = "auto", None
    for layer in layers:
        kind = layer.get("kind", kind)
        fmt = layer.get("format", fmt)
    if kind != "auto":
        return str(kind)
    brdf = Path(pattern).suffix.lower() in BRDF_SUFFIXES or fmt in BRDF_ONLY_FORMATS
    return "brdf" if brdf else "data"


def _check_channels(value: Any, where: str) -> tuple[int | str, ...] | None:
    if value is None:
        return None
    vals = value if isinstance(value, list) else [value]
    ok = vals and all(
        isinstance(v, str) or (isinstance(v, int) and not isinstance(v, bool) and v >= 0)
        for v in vals
    )
    if not ok:
        raise InputError(
            f"{where}: channels must be 0-based indices or channel names, got {value!r}"
        )
    return tuple(vals)


def settings_id(settings: Mapping[str, Any]) -> str:
    """Short hash of the settings that change a result (stable across runs and machines)."""
    keyed = {k: settings.get(k, DEFAULTS[k]) for k in sorted(DEFAULTS) if k not in _NOT_HASHED
             and not (k in _HASHED_IF_SET
                      and settings.get(k, DEFAULTS[k]) in _QUIET_VALUES[k])}
    text = json.dumps(keyed, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:10]


# ---------------------------------------------------------------------------- manifest
@dataclass(frozen=True)
class _Entry:
    index: int
    pattern: str
    where: str
    paths: tuple[Path, ...]
    labels: tuple[str, ...]
    channels: tuple[int | str, ...] | None
    combos: tuple[dict[str, Any], ...]


def load_manifest(
    manifest: str | os.PathLike[str] | Mapping[str, Any],
    base_dir: str | os.PathLike[str] | None = None,
) -> tuple[list[_Entry], Path, str]:
    """Parse and validate a manifest; returns (entries, base folder, name for messages)."""
    if isinstance(manifest, Mapping):
        doc: Any = manifest
        base = Path(base_dir) if base_dir is not None else Path.cwd()
        name = "manifest"
    else:
        path = Path(manifest)
        name = str(path)
        base = Path(base_dir) if base_dir is not None else path.resolve().parent
        doc = _read_manifest(path)
    base = base.resolve()
    if not isinstance(doc, Mapping):
        raise InputError(f"{name}: the manifest must be a table (JSON object)")
    for key in doc:
        if key not in TOP_KEYS:
            raise InputError(f"{name}: unknown key {key!r}; valid keys: {', '.join(TOP_KEYS)}")
    allowed = (*DEFAULTS, "channels")
    defaults = _check_table(doc.get("defaults", {}), f"{name}: defaults", allowed)
    top_channels = _check_channels(defaults.pop("channels", None), f"{name}: defaults")
    combos = _combos(doc.get("settings"), f"{name}: settings")
    inputs = doc.get("inputs")
    if isinstance(inputs, str):
        inputs = [inputs]
    if not isinstance(inputs, list) or not inputs:
        raise InputError(f"{name}: no inputs: give inputs = [\"data/*.csv\", ...]")
    entries = []
    for i, raw in enumerate(inputs):
        where = f"{name}: inputs[{i}]"
        if isinstance(raw, str):
            raw = {"path": raw}
        pattern = raw.get("path") if isinstance(raw, Mapping) else None
        if not isinstance(pattern, str) or not pattern.strip():
            raise InputError(f"{where}: needs a path (a file name or glob), got {pattern!r}")
        where = f"{where} ({pattern!r})"
        table = _check_table(raw, where, (*ENTRY_KEYS, *DEFAULTS))
        del table["path"]
        channels = _check_channels(table.pop("channels", None), where)
        if channels is None:
            channels = top_channels
        own = table.pop("settings", None)
        entry_combos = _combos(own, f"{where}: settings") if own is not None else combos
        kind = _entry_kind(pattern, (defaults, table))
        merged = []
        for j, combo in enumerate(entry_combos):
            s = _layered(BRDF_DEFAULTS if kind == "brdf" else DEFAULTS, defaults, combo, table)
            s["kind"] = kind
            _check_combined(s, where if len(entry_combos) == 1 else f"{where}, settings[{j}]")
            merged.append(s)
        paths, labels = _expand(pattern, base, where)
        entries.append(_Entry(i, pattern, where, paths, labels, channels, tuple(merged)))
    return entries, base, name


_WIDTH_KEYS = ("dt", "abs_width", "floor_rel")


def _layered(*layers: Mapping[str, Any]) -> dict[str, Any]:
    """Settings by precedence (later wins). dt and abs_width together are ONE width
    setting: a layer that gives either replaces the pair, so an entry's ``abs_width``
    overrides the defaults' ``dt`` instead of combining with it."""
    out: dict[str, Any] = {}
    for layer in layers:
        if any(k in layer for k in _WIDTH_KEYS):
            for k in _WIDTH_KEYS:
                out[k] = None
        out.update(layer)
    return out


def _read_manifest(path: Path) -> Any:
    if not path.is_file():
        raise InputError(f"{path}: no such manifest file")
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise InputError(f"{path}: a manifest must be a .toml or .json file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (not UTF-8)") from None
    if suffix == ".toml":
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{path}: invalid TOML: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from None


def _combos(raw: Any, where: str) -> tuple[dict[str, Any], ...]:
    if raw is None:
        return ({},)
    if not isinstance(raw, list) or not raw:
        raise InputError(f"{where}: must be a non-empty list of tables ([[settings]])")
    return tuple(_check_table(t, f"{where}[{j}]", tuple(DEFAULTS)) for j, t in enumerate(raw))


_MAGIC = re.compile(r"[*?\[]")


def _expand(pattern: str, base: Path, where: str) -> tuple[tuple[Path, ...], tuple[str, ...]]:
    """Files matched by ``pattern`` and their names relative to its fixed leading folders."""
    pat = Path(os.path.expanduser(pattern))
    full = pat if pat.is_absolute() else base / pat
    parts = full.parts
    fixed = 0
    while fixed < len(parts) - 1 and not _MAGIC.search(parts[fixed]):
        fixed += 1
    root = Path(*parts[:fixed])
    # abspath, not resolve(): a symlinked input keeps its own name, not its target's
    found = sorted(
        {Path(os.path.abspath(p)) for p in glob.glob(str(full), recursive=True)
         if Path(p).is_file()}
    )
    if not found:
        raise InputError(f"{where}: matched no file (looked for {full})")
    labels = []
    for p in found:
        try:
            rel = Path(os.path.relpath(p, os.path.abspath(root)))
        except ValueError:  # pragma: no cover (another drive on Windows)
            rel = Path(p.name)
        if ".." in rel.parts:
            rel = Path(p.name)
        labels.append(rel.with_suffix("").as_posix())
    return tuple(found), tuple(labels)


# ---------------------------------------------------------------------------- planning
@dataclass(frozen=True)
class Task:
    """One fit: what a worker needs, and the deterministic name of its result."""

    name: str
    input: str
    path: str
    input_sha256: str
    channel: str
    channel_index: int
    settings_id: str
    settings: dict[str, Any] = field(hash=False)


_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _safe(text: str) -> str:
    return _SAFE.sub("_", text).strip("._") or "_"


def result_name(label: str, shown: str, channel: str, sid: str) -> str:
    """``<input>.<channel>.<settings id>-<key>``: readable, and unique by construction.

    The readable part drops characters a file name cannot hold (channels ``a b`` and
    ``a_b`` read alike); ``key`` hashes the input as the summary names it, the exact
    channel name and the settings id, so two different fits never share a name.
    """
    key = hashlib.sha256(json.dumps([shown, channel, sid]).encode()).hexdigest()[:8]
    return f"{_safe(label.replace('/', '--'))}.{_safe(channel)}.{sid}-{key}"


def _display(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return str(path)


def plan(
    manifest: str | os.PathLike[str] | Mapping[str, Any],
    base_dir: str | os.PathLike[str] | None = None,
) -> tuple[list[Task], list[dict[str, Any]]]:
    """Every task of a manifest, in manifest order, plus rows for inputs that cannot be read.

    Each input is read once here (to learn its channels and check the segment
    options); a file that cannot be read is a "failed" row, not an error, so one
    bad file among hundreds does not stop the batch.
    """
    from ratfit.io.fitfile import file_sha256

    entries, base, _ = load_manifest(manifest, base_dir)
    tasks: list[Task] = []
    unreadable: list[dict[str, Any]] = []
    seen: dict[str, Task] = {}
    cache: dict[tuple[Any, ...], Any] = {}
    digests: dict[Path, str] = {}
    for e in entries:
        for path, label in zip(e.paths, e.labels, strict=True):
            shown = _display(path, base)
            for s in e.combos:
                sid = settings_id(s)
                key = (path, s["kind"], s["format"], s["dim"], s["color"])
                if key not in cache:
                    try:
                        cache[key] = _read_input(path, s)
                    except (RatfitError, OSError) as exc:
                        cache[key] = exc
                data = cache[key]
                if isinstance(data, Exception):
                    unreadable.append(_row(shown, "", sid, s, "failed", message=str(data)))
                    continue
                if s["kind"] == "data":
                    try:
                        data.segments(dt=s["dt"], abs_width=s["abs_width"])
                    except RatfitError as exc:
                        raise InputError(f"{e.where}: {exc}") from None
                if path not in digests:
                    digests[path] = file_sha256(path)
                for j, chan, s_task in _task_channels(e, data, shown, s):
                    name = result_name(label, shown, chan, sid)
                    task = Task(name, shown, str(path), digests[path], chan, j, sid, s_task)
                    prev = seen.get(name)
                    if prev is not None:
                        if (prev.path, prev.channel) != (task.path, task.channel):
                            # two different fits under one name: only a hash collision
                            raise InputError(
                                f"{e.where}: {prev.path} channel {prev.channel!r} and {path} "
                                f"channel {chan!r} both give the result name {name!r}"
                            )
                        continue  # the same fit asked for twice
                    seen[name] = task
                    tasks.append(task)
    return tasks, unreadable


def _read_input(path: Path, s: Mapping[str, Any]) -> Any:
    """An input as its kind reads it (a BRDF file's channels after the colour conversion)."""
    if s["kind"] == "brdf":
        from ratfit.brdf.io import read_brdf, samples_dataset

        return samples_dataset(read_brdf(path, fmt=s["format"]), None, color=s["color"])
    from ratfit.io.data import read_data

    return read_data(path, fmt=s["format"], dim=s["dim"])


def _task_channels(e: _Entry, data: Any, shown: str, s: dict[str, Any]
                   ) -> list[tuple[int, str, dict[str, Any]]]:
    """(channel index, channel label, task settings) of each task of one input: one per
    channel of a data file; one for a BRDF file's channels together (index -1), which
    its settings name, as `ratfit brdf fit --channel` does."""
    picked = _channel_indices(e, data, shown)
    if s["kind"] != "brdf":
        return [(j, data.output_names[j], s) for j in picked]
    names = [data.output_names[j] for j in picked]
    chosen = names if e.channels is not None else []
    return [(-1, ",".join(names), {**s, "channels": chosen})]


def _channel_indices(e: _Entry, data: Any, shown: str) -> list[int]:
    names = list(data.output_names)
    if e.channels is None:
        return list(range(len(names)))
    out = []
    for c in e.channels:
        if isinstance(c, int):
            if c >= len(names):
                raise InputError(
                    f"{e.where}: channel {c} does not exist in {shown} "
                    f"({len(names)} channel(s): {', '.join(names)})"
                )
            out.append(c)
        elif c in names:
            out.append(names.index(c))
        else:
            raise InputError(
                f"{e.where}: no channel named {c!r} in {shown} (channels: {', '.join(names)})"
            )
    return list(dict.fromkeys(out))


def _row(input_: str, channel: str, sid: str, settings: Mapping[str, Any], status: str, *,
         message: str = "", **values: Any) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(
        input=input_, channel=channel, settings_id=sid, status=status, message=message,
        settings=json.dumps({k: settings[k] for k in sorted(settings)}, separators=(",", ":")),
        resumed=False, verified=False, fit_file="",
    )
    row.update(values)
    return row


# ---------------------------------------------------------------------------- worker side
_DATA: OrderedDict[tuple, Any] = OrderedDict()
_DATA_KEEP = 4


def _dataset(path: str, fmt: str | None, dim: int | None) -> Any:
    """Read an input once per worker process (tasks of one input share it)."""
    from ratfit.io.data import read_data

    st = os.stat(path)
    key = (path, fmt, dim, st.st_mtime_ns, st.st_size)
    if key in _DATA:
        _DATA.move_to_end(key)
        return _DATA[key]
    data = read_data(path, fmt=fmt, dim=dim)
    _DATA[key] = data
    while len(_DATA) > _DATA_KEEP:
        _DATA.popitem(last=False)
    return data


def execute(task: Task) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """Run one task (on a worker): its summary row and, when verified, its fit document.

    Never raises for a bad fit or bad data: the exception becomes a "failed" row
    with its message, so one task cannot stop the batch.
    """
    t0 = time.perf_counter()
    s = task.settings
    base = (task.input, task.channel, task.settings_id, s)
    try:
        from ratfit.jobs import fit_brdf_file, fit_file

        report: Any
        request = request_of({**s, "channels": [task.channel_index]} if s["kind"] == "data"
                             else s, Path(task.path))
        if isinstance(request, BRDFFitRequest):
            report = fit_brdf_file(request)
        else:
            report = fit_file(request, data=_dataset(task.path, s["format"], s["dim"]))
        values = _row_values(report.results)
        values["wall_seconds"] = round(time.perf_counter() - t0, 6)
        if not report.success:
            message = "; ".join(r.message for r in report.results if not r.success)
            return _row(*base, "no-fit", message=message, **values), None
        doc = report.document()
        doc["provenance"]["input"] = task.input  # as the manifest names it
        return _row(*base, "ok", message="; ".join(getattr(report, "messages", [])),
                    **values), doc
    except Exception as exc:  # one task's failure is a row, never the batch's
        msg = f"{type(exc).__name__}: {exc}" if not isinstance(exc, RatfitError) else str(exc)
        if not isinstance(exc, RatfitError):
            where = traceback.extract_tb(exc.__traceback__)[-1]
            msg += f" (at {Path(where.filename).name}:{where.lineno})"
        return _row(*base, "failed", message=msg,
                    wall_seconds=round(time.perf_counter() - t0, 6)), None


def _row_values(results: list[Any]) -> dict[str, Any]:
    """A task's summary columns: its channel's, or over a BRDF file's channels the
    total, the worst errors and the sums (n and m per channel are in the fit file)."""
    per = [r.summary() for r in results]
    if len(per) == 1:
        keys = ("n", "m", "total", "verified", "linf", "l2", "max_rel_error", "max_violation",
                "qp_solves", "seconds")
        return {k: per[0][k] for k in keys}

    def worst(key: str) -> float | None:
        vals = [p[key] for p in per]
        return None if any(v is None for v in vals) else max(vals)

    return {"n": None, "m": None, "total": sum(p["total"] for p in per),
            "verified": all(p["verified"] for p in per), "linf": worst("linf"),
            "l2": worst("l2"), "max_rel_error": worst("max_rel_error"),
            "max_violation": worst("max_violation"),
            "qp_solves": sum(p["qp_solves"] for p in per),
            "seconds": sum(p["seconds"] for p in per)}


# ---------------------------------------------------------------------------- results on disk
@dataclass
class BatchSummary:
    """What a batch did: one row per task (plan order), and where the files are."""

    rows: list[dict[str, Any]]
    outdir: Path
    csv: Path
    parquet: Path
    fitted: int = 0
    skipped: int = 0

    @property
    def counts(self) -> dict[str, int]:
        out = dict.fromkeys(STATUSES, 0)
        for r in self.rows:
            out[r["status"]] += 1
        return out

    @property
    def ok(self) -> bool:
        return all(r["status"] == "ok" for r in self.rows)

    @property
    def success(self) -> bool:
        """The result vocabulary's name for ``ok``: every task has a verified fit."""
        return self.ok

    @property
    def message(self) -> str:
        c = self.counts
        return (f"{len(self.rows)} task(s): {c['ok']} ok, {c['no-fit']} without a verified "
                f"fit, {c['failed']} failed")


def _fit_path(outdir: Path, task: Task) -> Path:
    return outdir / f"{task.name}.json"


def _row_path(outdir: Path, task: Task) -> Path:
    return outdir / ROWS_DIR / f"{task.name}.json"


def _previous(outdir: Path, task: Task) -> dict[str, Any] | None:
    """The stored row of a finished task, if it is for the same input content.

    A fit file is believed only after the checks a first run would pass: it loads
    (digest, field types, no pole), it is one verified channel of this input's content,
    channel and settings, and its function meets this task's segments on the data.
    Anything else is fitted again (and atomically replaced)."""
    fp = _fit_path(outdir, task)
    if fp.is_file():
        row = _verified_result(fp, task)
        if row is not None:
            return row
    rp = _row_path(outdir, task)
    if rp.is_file():
        try:
            row = json.loads(rp.read_text())
            same = row.get("input_sha256") == task.input_sha256
            if same and row["status"] in ("no-fit", "failed"):
                return row
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass
    return None


def _verified_result(path: Path, task: Task) -> dict[str, Any] | None:
    """The summary row of a result file that re-verifies for ``task``, else None."""
    import numpy as np

    from ratfit.core.segments import Segments
    from ratfit.io.fitfile import load_fit, segment_check

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # an old or edited file is refitted, not used
            saved = load_fit(path, trust_edited=False)
        prov = saved.provenance
        row = prov.get("batch")
        if (saved.integrity != "sealed" or not saved.verified or not isinstance(row, dict)
                or ",".join(c.name for c in saved.channels) != task.channel
                or prov.get("input_sha256") != task.input_sha256
                or row.get("settings_id") != task.settings_id or row.get("status") != "ok"):
            return None
        s = task.settings
        if s.get("kind") == "brdf":
            # a BRDF file's fit: its block loads too (parametrization, dropped coordinates);
            # its segments are not rebuilt here (the default widths are the fit's own)
            from ratfit.brdf.fitter import load_brdf_fit

            load_brdf_fit(path)
            return {**row, "verified": True}
        seg = _dataset(task.path, s["format"], s["dim"]).segments(dt=s["dt"],
                                                                  abs_width=s["abs_width"])
        j = task.channel_index
        seg = Segments(seg.x, seg.lo[:, [j]], seg.hi[:, [j]], None, (seg.names[j],))
        dom = saved.space.domain
        pad = 1e-12 * (dom[:, 1] - dom[:, 0])
        if seg.x.shape[1] != dom.shape[0] or not np.all(
                (seg.x >= dom[:, 0] - pad) & (seg.x <= dom[:, 1] + pad)):
            return None  # data outside the fit's domain: nothing says it has no pole there
        _, met, total, _ = segment_check(saved, seg)[0]
        if met != total:
            return None
    except Exception:  # unreadable, foreign or inconsistent: fit again
        return None
    rf = saved.channels[0].rational
    return {**row, "n": rf.n, "m": rf.m, "total": rf.total, "verified": True}


def _store(outdir: Path, task: Task, row: dict[str, Any], doc: dict[str, Any] | None) -> None:
    """Write one result atomically and drop what it supersedes."""
    if doc is not None:
        row["fit_file"] = _fit_path(outdir, task).name
        doc["provenance"]["command"] = sys.argv
        doc["provenance"]["batch"] = _public(row)
        from ratfit.io.fitfile import save_fit

        save_fit(_fit_path(outdir, task), doc)
        _row_path(outdir, task).unlink(missing_ok=True)
    else:
        stored = {**_public(row), "input_sha256": task.input_sha256}
        with atomic_open(_row_path(outdir, task)) as fh:
            json.dump(stored, fh, indent=1, allow_nan=False)
        _fit_path(outdir, task).unlink(missing_ok=True)


def _public(row: Mapping[str, Any]) -> dict[str, Any]:
    return {k: row.get(k) for k in COLUMNS}


def write_summary(rows: list[dict[str, Any]], outdir: Path) -> tuple[Path, Path]:
    """summary.csv and summary.parquet (atomic), one row per task."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    csv_path = outdir / f"{SUMMARY_STEM}.csv"
    pq_path = outdir / f"{SUMMARY_STEM}.parquet"
    public = [_public(r) for r in rows]
    with atomic_open(csv_path, "w") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        w.writeheader()
        for r in public:
            w.writerow({k: "" if v is None else v for k, v in r.items()})
    types = {"n": pa.int64(), "m": pa.int64(), "total": pa.int64(), "qp_solves": pa.int64(),
             "verified": pa.bool_(), "resumed": pa.bool_()}
    for k in ("linf", "l2", "max_rel_error", "max_violation", "seconds", "wall_seconds"):
        types[k] = pa.float64()
    schema = pa.schema([(k, types.get(k, pa.string())) for k in COLUMNS])
    table = pa.Table.from_pylist(public, schema=schema)
    with atomic_path(pq_path) as tmp:
        pq.write_table(table, tmp)
    return csv_path, pq_path


# ---------------------------------------------------------------------------- running
def _require() -> None:
    missing = []
    for mod in ("distributed", "pyarrow"):
        try:
            __import__(mod)
        except ImportError:
            missing.append(mod)
    if missing:
        raise MissingDependency(
            f"batch fitting needs {' and '.join(missing)}, which is not installed: "
            f"{INSTALL_HINT}"
        )


MAIN_GUARD_HINT = (
    "the local Dask cluster starts worker processes that import your script again: put the "
    "call under `if __name__ == \"__main__\":` (or pass scheduler= / client=)"
)


def _check_main_guard() -> None:
    """A script calling run() at top level, without a ``__main__`` guard, makes every
    spawned worker run it again (Dask dies in its bootstrapping). Say so before starting."""
    main_mod = sys.modules.get("__main__")
    if getattr(main_mod, "__name__", "") == "__mp_main__":
        raise InputError(f"ratfit.batch.run() called while a worker imports the script: "
                         f"{MAIN_GUARD_HINT}")
    path = getattr(main_mod, "__file__", None)
    if not path or getattr(main_mod, "__spec__", None) is not None:
        return  # interactive, -c, or python -m (a module's own guard applies)
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return
    if "__main__" not in text:
        raise InputError(f"{path}: {MAIN_GUARD_HINT}")


@contextlib.contextmanager
def _cluster(client: Any, scheduler: str | None, workers: int | None, allowed_failures: int):
    """The client to use; a LocalCluster or a connection we open is closed on exit."""
    if client is not None:
        yield client
        return
    import logging

    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            own = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:  # ValueError: not an address
            raise InputError(f"cannot connect to the Dask scheduler at {scheduler!r}: {exc} "
                             "(give an address such as tcp://host:8786)") from None
        try:
            yield own
        finally:
            own.close()
        return
    _check_main_guard()
    n = workers or os.cpu_count() or 1
    with dask.config.set({"distributed.scheduler.allowed-failures": allowed_failures}):
        cluster = LocalCluster(n_workers=n, processes=True, threads_per_worker=1,
                               dashboard_address=None, silence_logs=logging.ERROR)
    try:
        own = Client(cluster)
        try:
            yield own
        finally:
            own.close()
    finally:
        cluster.close()


def run(
    manifest: str | os.PathLike[str] | Mapping[str, Any],
    client: Any = None,
    *,
    outdir: str | os.PathLike[str],
    scheduler: str | None = None,
    workers: int | None = None,
    base_dir: str | os.PathLike[str] | None = None,
    rerun_failed: bool = False,
    allowed_failures: int = 3,
    progress: bool = False,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> BatchSummary:
    """Fit every (input, channel, settings) of ``manifest`` on Dask; returns the summary.

    ``client``: an existing ``distributed.Client`` (kept open). Else ``scheduler``
    (address of a running scheduler) or a LocalCluster of ``workers`` processes
    (default: one per core, one thread each) started and stopped here;
    ``allowed_failures`` (that cluster only) is how many worker deaths a task may
    witness before it is reported as failed. ``on_result(row)`` is called after each
    result is written (progress hooks; raising KeyboardInterrupt stops the batch
    like Ctrl-C). Ctrl-C cancels the remaining tasks and raises
    :class:`BatchInterrupted` (a KeyboardInterrupt) carrying the summary so far.
    """
    _require()
    if isinstance(allowed_failures, bool) or not isinstance(allowed_failures, int) \
            or allowed_failures < 0:
        raise InputError(f"allowed_failures must be an integer >= 0, got {allowed_failures!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise InputError(f"workers must be an integer >= 1, got {workers!r}")
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: output folder is a file")
    tasks, unreadable = plan(manifest, base_dir)
    todo_args = (tasks, unreadable, client, scheduler, workers, allowed_failures, progress,
                 on_result, rerun_failed)
    if out.is_dir():
        # an existing folder holds earlier results: each result is written into it
        # atomically as it comes (what a resumed run picks up)
        return _run_into(out, out, *todo_args)
    # a new folder is built beside its place and moved there at the end (also after
    # Ctrl-C: what is finished is kept for the next run); on an error nothing is left
    stopped: BatchInterrupted | None = None
    with atomic_dir(out) as work:
        try:
            summary = _run_into(work, out, *todo_args)
        except BatchInterrupted as exc:
            stopped = exc
    if stopped is not None:
        raise stopped
    return summary


def _run_into(work: Path, out: Path, tasks: list[Task], unreadable: list[dict[str, Any]],
              client: Any, scheduler: str | None, workers: int | None, allowed_failures: int,
              progress: bool, on_result: Callable[[dict[str, Any]], None] | None,
              rerun_failed: bool) -> BatchSummary:
    """Run ``tasks`` writing into ``work``; the summary names files in ``out``."""
    rows: dict[str, dict[str, Any]] = {}
    todo: list[Task] = []
    for t in tasks:
        prev = _previous(work, t)
        if prev is not None and (prev["status"] == "ok" or not rerun_failed):
            rows[t.name] = {**_public(prev), "resumed": True}
        else:
            todo.append(t)
    summary = BatchSummary([], out, out / f"{SUMMARY_STEM}.csv",
                           out / f"{SUMMARY_STEM}.parquet", skipped=len(rows))

    def finish(partial: bool) -> BatchSummary:
        ordered = []
        for t in tasks:
            r = rows.get(t.name)
            if r is None and partial:
                r = _row(t.input, t.channel, t.settings_id, t.settings, "pending",
                         message="not run (interrupted)")
            if r is not None:
                ordered.append(r)
        summary.rows = ordered + unreadable
        csv_path, pq_path = write_summary(summary.rows, work)
        summary.csv, summary.parquet = out / csv_path.name, out / pq_path.name
        return summary

    if not todo:
        return finish(False)
    with _cluster(client, scheduler, workers, allowed_failures) as cl:
        from distributed import as_completed

        # done / total, failed so far, time spent and left (from the tasks run now:
        # resumed ones are counted, not timed); a bar on a terminal, else a line at
        # most every PROGRESS_EVERY seconds and at the end
        bar = StepProgress("batch", len(tasks), enabled=progress, done=len(rows),
                           every=lambda: PROGRESS_EVERY).start()
        failed = 0
        tag = uuid.uuid4().hex[:8]
        futures: dict[Any, Task] = {}
        try:
            for t in todo:
                futures[cl.submit(execute, t, key=f"ratfit-{t.name}-{tag}", pure=False)] = t
            for fut in as_completed(futures):
                t = futures[fut]
                try:
                    row, doc = fut.result()
                except Exception as exc:  # KilledWorker, lost data, cancellation by others
                    row, doc = _row(t.input, t.channel, t.settings_id, t.settings, "failed",
                                    message=f"{type(exc).__name__}: {exc}"), None
                _store(work, t, row, doc)
                rows[t.name] = row
                summary.fitted += 1
                failed += row["status"] != "ok"
                bar.advance(1, status=f"{failed} failed or no fit")
                if on_result is not None:
                    on_result(_public(row))
        except KeyboardInterrupt:
            cl.cancel(list(futures))
            bar.stop()
            raise BatchInterrupted(finish(True)) from None
        finally:
            bar.stop()
    return finish(False)


# seconds between progress lines in a log (no terminal)
PROGRESS_EVERY = 5.0

