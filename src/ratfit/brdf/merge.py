"""Channels of one BRDF measurement fitted in separate runs, as one fit file.

A ``brdf fit`` whose channels did not all verify keeps the ones that did in a file of
their own (:func:`channel_meta` cuts the ``brdf`` block down to them); the others are
refitted alone (``--channel R``, wider segments, more time) and
:func:`merge_fit_documents` joins the files. Every file must describe the same fit of
the same data (input digest, frame, value form, subset, basis and domain): only then is
each channel's stored proof a proof of the merged file's channel.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ratfit.errors import InputError
from ratfit.io.fitfile import run_provenance

__all__ = ["PER_CHANNEL", "SAME_FIT", "channel_meta", "merge_fit_documents"]

#: ``brdf`` block keys that hold one entry per channel, in channel order.
PER_CHANNEL = ("channel_names", "validity", "proof", "held_out_size")
#: ``brdf`` block keys every merged file must agree on: how a channel is evaluated
#: (frame, value form, dropped coordinates, clamp), what its proof covers (envelope,
#: subset) and how it was fitted where a file states one value for all channels.
SAME_FIT = ("parametrization", "values", "cosine_weighted", "fold_phi_d", "dropped_coords",
            "clamp", "param_out", "subset", "verified_on", "envelope", "positive_q",
            "polish", "polish_error")
# segment keys that differ per run and are kept per channel (channel_dt, abs_width) or
# only in the run's record under "merged_from"
_RUN_SEGMENT_KEYS = ("dt", "abs_width", "channel_dt", "widened_from", "narrowed_floor_from")


def channel_meta(meta: Mapping[str, Any], keep: Sequence[int]) -> dict[str, Any]:
    """The ``brdf`` block of a fit file that holds only the channels ``keep`` (indices
    into ``meta["channel_names"]``): per-channel lists and per-channel widths cut to
    them. A shared denominator ties every channel to one q: its channels are not
    separable (InputError)."""
    if meta.get("shared_denominator"):
        raise InputError("the channels of a fit with one shared denominator cannot be kept "
                         "apart: they share q")
    n = len(meta["channel_names"])
    out = dict(meta)
    for key in PER_CHANNEL:
        if isinstance(meta.get(key), list) and len(meta[key]) == n:
            out[key] = [meta[key][j] for j in keep]
    hold = meta.get("holdout")
    if isinstance(hold, dict) and isinstance(hold.get("metrics"), dict):
        # the folds' held-out errors of the kept channels (the folds themselves fitted all)
        names = {str(meta["channel_names"][j]) for j in keep}
        out["holdout"] = {**hold, "metrics": {k: v for k, v in hold["metrics"].items()
                                              if k in names}}
    seg = dict(meta.get("segments") or {})
    for key in ("channel_dt", "abs_width"):
        if isinstance(seg.get(key), list) and len(seg[key]) == n:
            seg[key] = [seg[key][j] for j in keep]
    out["segments"] = seg
    return out


def merge_fit_documents(docs: Sequence[Mapping[str, Any]], wheres: Sequence[str],
                        *, order: Sequence[str] | None = None) -> dict[str, Any]:
    """One fit file's document holding every channel of ``docs`` (checked, sealed fit
    files of ``ratfit brdf fit``; ``wheres`` name them in messages).

    Channels come in the order of the input file (``provenance.input_channels``, which
    ``brdf fit`` records) or ``order``, else as given. The result is not sealed: save it
    with :func:`ratfit.io.fitfile.save_fit`, which computes its digest.
    """
    if len(docs) < 2:
        raise InputError("merge needs two or more fit files")
    metas = [_brdf_block(d, w) for d, w in zip(docs, wheres, strict=True)]
    first, where0 = docs[0], wheres[0]
    for d, m, w in zip(docs[1:], metas[1:], wheres[1:], strict=True):
        _same(first["provenance"].get("input_sha256"), d["provenance"].get("input_sha256"),
              f"{w} fits other data than {where0} (input_sha256 differs)")
        _same(first["space"], d["space"], f"{w} has another basis or domain than {where0} "
              "(space differs: fits of the same data in the same frame share it)")
        for key in SAME_FIT:
            _same(metas[0].get(key), m.get(key),
                  f"{w} and {where0} differ in brdf.{key} ({_short(metas[0].get(key))} vs "
                  f"{_short(m.get(key))}): ratfit merges fits made with the same {key}")
    # each channel with its run: (name, channel dict, per-channel entries, file index)
    rows: list[tuple[str, dict[str, Any], dict[str, Any], int]] = []
    for i, (d, m) in enumerate(zip(docs, metas, strict=True)):
        names = [str(c["name"]) for c in d["channels"]]
        if names != [str(v) for v in m["channel_names"]]:
            raise InputError(f"{wheres[i]}: brdf.channel_names {m['channel_names']} do not "
                             f"match its channels {names}")
        for j, (name, ch) in enumerate(zip(names, d["channels"], strict=True)):
            rows.append((name, ch, _entries(m, j, len(names)), i))
    seen: dict[str, int] = {}
    for name, _, _, i in rows:
        if name.lower() in seen:
            raise InputError(f"channel {name} is in {wheres[seen[name.lower()]]} and in "
                             f"{wheres[i]}: merge joins files of different channels")
        seen[name.lower()] = i
    rank = _order(docs, order)
    if rank:
        rows.sort(key=lambda r: rank.get(r[0].lower(), len(rank)))
    meta = {k: v for k, v in metas[0].items() if k not in ("candidates", "holdout", "shared")}
    for key in PER_CHANNEL:
        vals = [r[2].get(key) for r in rows]
        if key == "held_out_size" and all(v is None for v in vals):
            meta.pop(key, None)
        else:
            meta[key] = vals
    meta["segments"] = _segments(metas, rows, wheres)
    meta["merged_from"] = [_run(d, m, w) for d, m, w in zip(docs, metas, wheres, strict=True)]
    prov = run_provenance()
    for key in ("input", "input_sha256", "n_points", "solver", "segments", "input_channels"):
        vals = [d["provenance"].get(key) for d in docs]
        if all(v == vals[0] for v in vals) and vals[0] is not None:
            prov[key] = vals[0]
    return {"format": first["format"], "version": first["version"], "space": first["space"],
            "channels": [r[1] for r in rows], "provenance": prov, "brdf": meta}


def _brdf_block(doc: Mapping[str, Any], where: str) -> dict[str, Any]:
    meta = doc.get("brdf")
    if not isinstance(meta, dict) or not isinstance(meta.get("channel_names"), list):
        raise InputError(f"{where}: not a fit file of ratfit brdf fit (no brdf block): "
                         "merge joins the channels of BRDF fits")
    if meta.get("shared_denominator"):
        raise InputError(f"{where}: its channels share one denominator; merge joins fits "
                         "of separate channels")
    if not isinstance(doc.get("provenance"), dict):
        raise InputError(f"{where}: no provenance: merge needs the input's digest")
    return meta


def _entries(meta: Mapping[str, Any], j: int, n: int) -> dict[str, Any]:
    """Channel j's per-channel entries and widths of a file's brdf block."""
    out = {k: meta[k][j] if isinstance(meta.get(k), list) and len(meta[k]) == n else None
           for k in PER_CHANNEL}
    seg = meta.get("segments") or {}
    cdt = seg.get("channel_dt")
    out["dt"] = cdt[j] if isinstance(cdt, list) and len(cdt) == n else seg.get("dt")
    aw = seg.get("abs_width")
    out["abs_width"] = aw[j] if isinstance(aw, list) and len(aw) == n else aw
    return out


def _segments(metas: Sequence[Mapping[str, Any]], rows: Sequence[tuple[str, Any, Any, int]],
              wheres: Sequence[str]) -> dict[str, Any]:
    """One segments block for the merged channels. Each channel keeps the widths its run
    fitted it with: when they differ, ``per_channel`` lists them (dt, abs_width,
    floor_rel), which :func:`ratfit.viz.report.segments_of` rebuilds channel by channel."""
    blocks = [dict(m.get("segments") or {}) for m in metas]
    specs = [{"dt": r[2]["dt"], "abs_width": r[2]["abs_width"],
              "floor_rel": blocks[r[3]].get("floor_rel")} for r in rows]
    if any(isinstance(s["abs_width"], str) for s in specs):
        raise InputError(f"{wheres[0]}: a floor recorded as 'auto' without the values found")
    out = {k: v for k, v in blocks[0].items() if k not in _RUN_SEGMENT_KEYS}
    out.update(specs[0])
    out["channel_dt"] = None
    if any(s != specs[0] for s in specs):
        out["per_channel"] = specs
    out["default"] = all(bool(b.get("default")) for b in blocks)
    out["noise_estimated"] = all(bool(b.get("noise_estimated")) for b in blocks)
    return out


def _run(doc: Mapping[str, Any], meta: Mapping[str, Any], where: str) -> dict[str, Any]:
    """What a merged file keeps of each run: where it came from and how it searched."""
    prov = doc["provenance"]
    out = {"file": where, "digest": doc.get("digest"), "channels": list(meta["channel_names"]),
           "created": prov.get("created"), "command": prov.get("command"),
           "segments": meta.get("segments"), "candidates": meta.get("candidates")}
    if meta.get("holdout") is not None:
        out["holdout"] = meta["holdout"]
    return out


def _order(docs: Sequence[Mapping[str, Any]], order: Sequence[str] | None) -> dict[str, int]:
    """Rank of each channel name: ``order``, else the input's channel order as the files
    that record it agree on (files written before ratfit recorded it have none)."""
    if order is None:
        given = [g for d in docs if isinstance(g := d["provenance"].get("input_channels"), list)]
        if not given or any(g != given[0] for g in given):
            return {}
        order = given[0]
    return {str(n).lower(): i for i, n in enumerate(order)}


def _same(a: Any, b: Any, message: str) -> None:
    if a != b:
        raise InputError(message)


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."
