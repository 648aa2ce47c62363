"""RGL materials as full MERL tables, fitted by default (issue 28).

Each of the 51 neural encodings in ``../shared/data/nbrdf-rgl/`` (a 675-weight
network per measured isotropic RGL material, see SOURCES.md) is written as a
full 90x90x180 MERL .binary (:mod:`ratfit.brdf.nbrdf`), then fitted by
``ratfit brdf fit TABLE -o fit.json --json`` with no other option, in a fresh
process whose peak memory (ru_maxrss of that process alone) and wall time are
reported. The fit is then compared with the network at 1e5 seeded random direction
pairs: L and V each uniform on the upper hemisphere ("all"), and each uniform on
the cap cos(theta) >= 0.1 ("cos>0.1"). Per channel: coefficients (n + m), median
and 95th percentile of |f - y| / max(y, 1e-3 1/sr). Goal (issue 28): median < 5 %
and p95 < 25 % in every channel with at most 675 numbers in all.

    nice -n 10 python benchmarks/bench_rgl.py [--only NAME ...] [--limit N] [--timeout 400]
        [--pairs 100000] [--data DIR] [--baseline SRC] [--fit-args ARGS] [--baseline-args ARGS]

A material whose fit runs past --timeout, or exits without a fit file, is reported
as such (no errors); when some channels verified and ``brdf fit`` kept them
(``fit.partial.json``), those channels are scored and the others marked "none".
``--known`` runs first a material known in closed form, the Lambert + two GGX lobes
of bench_merl.py, written and fitted the same way (issue 28: back within 5 % median
and 25 % at the 95th percentile).

Each material's first rows are the table itself, read back and looked up as MERL's
reference reader does, at the same pairs: what the fit is given, as a renderer would use
it. ``--table-only`` gives those rows alone (seconds a material, all 51 in minutes).

``--baseline SRC`` (the ``src`` folder of another checkout, e.g. main's) fits each table
with that code too, in the same run, just before this code's fit: a second row per
channel, the ratios of this code's seconds, CPU seconds (user + system of the fit's
process, less sensitive to other processes than the wall time) and peak memory to the
baseline's, and whether the two fits' coefficients are identical. The load average
before each fit is printed. ``--fit-args "--values log"`` adds options to this code's fit,
``--baseline-args`` to the baseline's: with ``--baseline`` set to this checkout's own
``src``, two options are compared on the same tables in one run.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = Path(os.environ.get("RATFIT_SHARED_DATA", REPO.parent / "shared" / "data"))
FLOOR = 1e-3  # 1/sr: below this a relative error is taken against the floor
MAX_NUMBERS = 675  # the network's own size

# Runs ``ratfit brdf fit`` in its own session (so a timeout kills every worker it
# started) and reports the child's wall time, exit status and peak RSS as JSON.
_CHILD = r"""
import json, os, resource, signal, subprocess, sys, time
table, out, timeout = sys.argv[1], sys.argv[2], float(sys.argv[3])
cmd = [sys.executable, "-m", "ratfit", "brdf", "fit", table, "-o", out, "--json",
       *json.loads(sys.argv[4])]
t0 = time.perf_counter()
p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                     start_new_session=True)
try:
    so, se = p.communicate(timeout=timeout)
    rc = p.returncode
except subprocess.TimeoutExpired:
    os.killpg(p.pid, signal.SIGKILL)
    so, se = p.communicate()
    rc = None
dt = time.perf_counter() - t0
use = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"rc": rc, "seconds": dt, "peak_mb": use.ru_maxrss / 1024.0,
                  "cpu": use.ru_utime + use.ru_stime, "stdout": so[-20000:],
                  "stderr": se[-2000:]}))
"""


def _clip(text: str, most: int = 200) -> str:
    """``text`` cut at a word boundary to at most ``most`` characters, " ..." marking a
    cut (a table cell, not a word cut in half)."""
    if len(text) <= most:
        return text
    return text[:most].rsplit(" ", 1)[0] + " ..."


def hemisphere(rng: np.random.Generator, n: int, zmin: float) -> np.ndarray:
    """Directions uniform (by solid angle) on the cap z in (zmin, 1]."""
    z = rng.uniform(zmin, 1.0, n)
    z = np.where(z <= 0.0, 1e-12, z)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def seeded_pairs(n_pairs: int, zmin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's pairs: L and V uniform on the cap z > ``zmin``, seed 2026 (every
    script that scores or counts RGL pairs draws these)."""
    rng = np.random.default_rng(2026)
    return hemisphere(rng, n_pairs, zmin), hemisphere(rng, n_pairs, zmin)


def errors(fit_path: Path, net, n_pairs: int,
           columns: list[int] | None = None) -> dict[str, np.ndarray]:
    """(2, k) median and p95 relative errors of the fit per distribution name; ``columns``:
    the network's channels the fit's k channels are (default all, in order)."""
    from ratfit.brdf.fitter import load_brdf_fit

    return pair_errors(load_brdf_fit(fit_path), net, n_pairs, columns)


class TableLookup:
    """The MERL table a fit is given, read back and looked up as MERL's reference reader
    does (each pair's cell, indices rounded down); a missing cell (its point below the
    horizon) is 0, as a renderer that clamps the stored -1 sees it."""

    def __init__(self, table: Path) -> None:
        from ratfit.brdf.io import read_merl

        self.merl = read_merl(table)

    def eval_dirs(self, L: np.ndarray, V: np.ndarray) -> np.ndarray:
        return np.nan_to_num(self.merl.lookup(L, V), nan=0.0)


def pair_errors(model, net, n_pairs: int,
                columns: list[int] | None = None) -> dict[str, np.ndarray]:
    """(2, k) median and p95 relative errors of ``model.eval_dirs`` against ``net``
    (its ``columns``) per distribution name (the same seeded pairs for every model)."""
    out = {}
    for label, zmin in (("all", 0.0), ("cos>0.1", 0.1)):
        L, V = seeded_pairs(n_pairs, zmin)
        y = net.eval_dirs(L, V)
        if columns is not None:
            y = y[:, columns]
        f = model.eval_dirs(L, V)
        rel = np.abs(f - y) / np.maximum(y, FLOOR)
        rel = np.where(np.isfinite(rel), rel, np.inf)
        out[label] = np.stack([np.median(rel, axis=0), np.percentile(rel, 95, axis=0)])
    return out


def coef_counts(fit_path: Path) -> list[int]:
    from ratfit.io.fitfile import load_fit

    return [c.rational.n + c.rational.m for c in load_fit(fit_path).channels]


def coefficients(fit_path: Path) -> list[tuple[list[float], list[float]]]:
    """Each channel's stored (p, q), as the fit file has them."""
    doc = json.loads(fit_path.read_text())
    return [(list(c["p"]), list(c["q"])) for c in doc["channels"]]


class KnownMaterial:
    """bench_merl.py's Lambert + two GGX lobes, shaped like an encoded material."""

    name = "known lambert+2ggx"
    n_weights = 0

    def eval_dirs(self, L: np.ndarray, V: np.ndarray) -> np.ndarray:
        from bench_merl import material  # benchmarks/bench_merl.py

        return material(L, V)

    __call__ = eval_dirs


def run_one(npz: Path | None, timeout: float, n_pairs: int,
            baseline: Path | None = None, fit_args: tuple[str, ...] = (),
            baseline_args: tuple[str, ...] = (), fit: bool = True,
            keep: Path | None = None) -> list[dict]:
    """The table's own lookup's errors, then the material's fit by this code with
    ``fit_args``; with ``baseline`` (a src folder) first by that code with
    ``baseline_args``, on the same table. ``fit`` False: the table's row alone."""
    from ratfit.brdf.io import merl_from_function, write_merl
    from ratfit.brdf.nbrdf import load_nbrdf

    net = KnownMaterial() if npz is None else load_nbrdf(npz)
    with tempfile.TemporaryDirectory(prefix="bench_rgl_") as tmp:
        table = Path(tmp) / f"{net.name}.binary"
        write_merl(table, merl_from_function(net))
        rows = [{"name": net.name, "code": "table",
                 "errors": pair_errors(TableLookup(table), net, n_pairs)}]
        if not fit:
            return rows
        srcs = ([("baseline", baseline, baseline_args)] if baseline is not None else []) + [
            ("this", REPO / "src", fit_args)]
        out = [fit_one(net, table, Path(tmp) / f"fit_{label}.json", timeout, n_pairs,
                       src, label, args) for label, src, args in srcs]
        if keep is not None:  # the fit files (and kept channels), for renders
            keep.mkdir(parents=True, exist_ok=True)
            for f in Path(tmp).glob("fit_*.json"):
                shutil.copy(f, keep / f"{net.name}_{f.name}")
        return rows + out


def fit_one(net, table: Path, out: Path, timeout: float, n_pairs: int, src: Path,
            label: str, args: tuple[str, ...] = ()) -> dict:
    """``ratfit brdf fit TABLE ARGS`` with the code in ``src``, scored against ``net``."""
    load = os.getloadavg()[0]
    env = {**os.environ, "PYTHONPATH": str(src)}
    res = subprocess.run([sys.executable, "-c", _CHILD, str(table), str(out), str(timeout),
                          json.dumps(list(args))],
                         capture_output=True, text=True, env=env, check=True)
    child = json.loads(res.stdout)
    row = {"name": net.name, "rc": child["rc"], "seconds": child["seconds"],
           "peak_mb": child["peak_mb"], "cpu": child["cpu"], "weights": net.n_weights,
           "code": label, "load": load}
    try:
        summary = json.loads(child["stdout"]) if child["stdout"].strip() else {}
    except json.JSONDecodeError:
        summary = {}
    row["summary_success"] = summary.get("success")
    if isinstance(summary.get("n"), list) and isinstance(summary.get("m"), list):
        pairs = zip(summary["n"], summary["m"], strict=True)
        row["coefs"] = [int(a) + int(b) for a, b in pairs]
    if child["rc"] is not None and child["rc"] != 0:
        row["why"] = child["stderr"].strip().splitlines()[-1:] or ["?"]
    kept = out.with_name(f"{out.stem}.partial.json")
    if out.exists():
        row["coefs"] = coef_counts(out)
        row["coefficients"] = coefficients(out)
        try:
            row["errors"] = errors(out, net, n_pairs)
        except Exception as exc:  # report it in the table, keep benchmarking
            row["why"] = [f"evaluation failed: {type(exc).__name__}: {exc}"]
    elif kept.exists():  # the channels that verified, kept by brdf fit
        from ratfit.io.fitfile import load_fit

        names = [c.name for c in load_fit(kept).channels]
        row["kept"] = names
        row["coefs"] = coef_counts(kept)
        try:
            row["errors"] = errors(kept, net, n_pairs, ["RGB".index(c) for c in names])
        except Exception as exc:
            row["why"] = [f"evaluation failed: {type(exc).__name__}: {exc}"]
    return row


def compare_coefficients(a: list | None, b: list | None) -> str:
    """Whether two fits' stored coefficients are identical, else how far apart."""
    if a is None or b is None:
        return "no fit to compare coefficients with"
    if a == b:
        return "coefficients identical"
    parts = []
    for (pa, qa), (pb, qb) in zip(a, b, strict=True):
        if (len(pa), len(qa)) != (len(pb), len(qb)):
            parts.append("other (n, m)")
            continue
        ca, cb = np.r_[pa, qa], np.r_[pb, qb]
        parts.append(f"{np.abs(ca - cb).max() / np.abs(ca).max():.1e}")
    return "coefficients differ (per channel, max |difference| / max |coefficient|: " \
        + ", ".join(parts) + ")"


def fmt_pct(x: float) -> str:
    return f"{100 * x:.1f}" if np.isfinite(x) and x < 1e4 else "inf"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA / "nbrdf-rgl")
    ap.add_argument("--only", nargs="*", help="material names (file stem, _rgb optional)")
    ap.add_argument("--limit", type=int, help="at most this many materials")
    ap.add_argument("--timeout", type=float, default=400.0, help="seconds per fit")
    ap.add_argument("--pairs", type=int, default=100_000, help="random direction pairs")
    ap.add_argument("--table-only", action="store_true",
                    help="only the tables' own lookup errors (no fit: seconds a material)")
    ap.add_argument("--known", action="store_true",
                    help="first the closed-form Lambert + 2 GGX material of bench_merl.py")
    ap.add_argument("--baseline", type=Path, metavar="SRC",
                    help="also fit each table with the code in SRC (another checkout's "
                         "src folder), just before this code; ratios this / baseline")
    ap.add_argument("--fit-args", default="", metavar="ARGS",
                    help="options added to this code's `ratfit brdf fit` (one string, "
                         "e.g. \"--values log\"); the table's title names them")
    ap.add_argument("--baseline-args", default="", metavar="ARGS",
                    help="options added to the baseline's fit (with --baseline; the same "
                         "src and other ARGS compare two options on the same tables)")
    ap.add_argument("--keep", type=Path, metavar="DIR",
                    help="copy each fit file (and a failed fit's kept channels) to DIR, "
                         "named MATERIAL_fit_this.json, ...")
    add_markdown_option(ap)
    args = ap.parse_args()
    fit_args, base_args = tuple(shlex.split(args.fit_args)), tuple(shlex.split(args.baseline_args))
    if args.baseline is not None and not (args.baseline / "ratfit").is_dir():
        sys.exit(f"error: --baseline {args.baseline}: no ratfit package in it")

    files = sorted(args.data.glob("*.npz"))
    if args.only:  # in the order given
        stem = {f.stem.removesuffix("_rgb"): f for f in files}
        files = [stem[w] for w in (o.removesuffix(".npz").removesuffix("_rgb")
                                   for o in args.only) if w in stem]
    if args.limit is not None:
        files = files[: args.limit]
    if not files and not args.known:
        sys.exit(f"error: no .npz material in {args.data} matches")
    runs: list[Path | None] = [None] if args.known else []
    runs += files

    rep = report(args, __file__)
    compare = args.baseline is not None
    header = ["material", "of", "ch", "n+m", "med% all",
              "p95% all", "med% c>.1", "p95% c>.1", "s", "cpu s", "peak MB", "load",
              "verified"]
    rows = []
    ratios = []
    met = table_met = 0
    for npz in runs:
        fits = run_one(npz, args.timeout, args.pairs, args.baseline, fit_args, base_args,
                       fit=not args.table_only, keep=args.keep)
        lookup, fits = fits[0], fits[1:]
        e = lookup["errors"]
        table_good = True
        for c, ch in enumerate("RGB"):
            med, p95 = e["all"][0, c], e["all"][1, c]
            table_good = table_good and med < 0.05 and p95 < 0.25
            rows.append([lookup["name"], "table", ch, "-", fmt_pct(med), fmt_pct(p95),
                         fmt_pct(e["cos>0.1"][0, c]), fmt_pct(e["cos>0.1"][1, c]),
                         "-", "-", "-", "-", "-"])
        table_met += table_good and npz is not None
        for r in fits:
            ok_fit = r["rc"] == 0 and "errors" in r
            status = ("yes" if ok_fit else f"timeout {args.timeout:.0f} s" if r["rc"] is None
                      else f"no (exit {r['rc']})")
            print(f"{r['name']} ({r['code']}): {status}, {r['seconds']:.0f} s",
                  file=sys.stderr, flush=True)
            code = ["fit" if r["code"] == "this" else "baseline fit"]
            common = [f"{r['seconds']:.0f}", f"{r['cpu']:.0f}", f"{r['peak_mb']:.0f}",
                      f"{r['load']:.1f}"]
            if "errors" not in r:
                nm = "/".join(map(str, r["coefs"])) if r.get("coefs") else "-"
                why = f" [{_clip(r['why'][0])}]" if r.get("why") else ""
                rows.append([r["name"], *code, "RGB", nm, "-", "-", "-", "-", *common,
                             status + why])
                continue
            e = r["errors"]
            good = ok_fit and sum(r["coefs"]) <= (MAX_NUMBERS if r["weights"] else 10**9)
            kept = r.get("kept")
            for ch in "RGB":
                if kept is not None and ch not in kept:
                    rows.append([r["name"], *code, ch, "-", "-", "-", "-", "-", *common,
                                 "none"])
                    continue
                c = kept.index(ch) if kept is not None else "RGB".index(ch)
                if kept is not None:
                    status = "kept (" + ", ".join(sorted(set("RGB") - set(kept),
                                                         key="RGB".index)) + ": none)"
                med, p95 = e["all"][0, c], e["all"][1, c]
                good = good and med < 0.05 and p95 < 0.25
                rows.append([r["name"], *code, ch, str(r["coefs"][c]), fmt_pct(med),
                             fmt_pct(p95), fmt_pct(e["cos>0.1"][0, c]),
                             fmt_pct(e["cos>0.1"][1, c]), *common, status])
            met += good and npz is not None and r["code"] == "this"
        if compare and len(fits) == 2:
            base, this = fits
            same = compare_coefficients(base.get("coefficients"), this.get("coefficients"))
            ratios.append(f"{this['name']}: this / baseline: "
                          f"{this['seconds'] / base['seconds']:.2f} s, "
                          f"{this['cpu'] / base['cpu']:.2f} cpu s, "
                          f"{this['peak_mb'] / base['peak_mb']:.2f} peak MB; {same}")
    note = (f"The tables themselves (MERL's lookup): {table_met} of {len(files)} materials "
            "with median < 5 % and p95 < 25 % (all pairs) in every channel.")
    if not args.table_only:
        note += (f" Fits: {met} of {len(files)} materials verified with median < 5 % and "
                 f"p95 < 25 % (all pairs) in every channel and <= {MAX_NUMBERS} numbers.")
    if ratios:
        note += (f" Baseline: the code in {args.baseline}, run just before this code on the "
                 "same table. " + ". ".join(ratios) + ".")
    what = " ".join(["`ratfit brdf fit TABLE -o fit.json", *fit_args]) + "`"
    if compare:
        what += " (baseline: " + " ".join(["`ratfit brdf fit TABLE -o fit.json",
                                           *base_args]) + "`)"
    if args.table_only:
        title = ("the full MERL tables' own lookup (no fit): MERL's reader's cell of each "
                 "pair (indices rounded down; a missing cell is 0)")
        header, rows = header[:8], [r[:8] for r in rows]
    else:
        title = (f"{what if fit_args or base_args else 'default ' + what} on full MERL "
                 f"tables; timeout {args.timeout:.0f} s; of: table = the MERL table the fit "
                 "is given, looked up as MERL's reader does (each pair's cell, indices "
                 "rounded down; a missing cell is 0), fit = its fit; s: wall seconds of the "
                 "fit's process, cpu s: its user + system seconds, load: the 1-minute load "
                 "average before it")
    rep.table(f"{title}; {args.pairs} seeded pairs, L and V uniform on the hemisphere (all) "
              f"or on the cap cos >= 0.1 (c>.1); rel = |f - y| / max(y, {FLOOR:g})",
              header, rows, note=note)
    rep.write()


if __name__ == "__main__":
    main()
