"""Write the tutorials' pictures into docs/img/ by running the commands the tutorials show.

    python docs/gen_figures.py            # every picture (a few minutes: BRDF fit and render)
    python docs/gen_figures.py --quick    # all but the BRDF pictures (about a minute)
    python docs/gen_figures.py --only brdf   # one group: addendum, fit_1d, cdf, batch, brdf

Each picture is the output of a `ratfit` command on data from ../shared/data (or
RATFIT_SHARED_DATA), downscaled to at most 900 pixels wide so the committed PNGs stay small.
The docs build does not run this script: the PNGs it writes are committed.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
DATA = Path(os.environ.get("RATFIT_SHARED_DATA", ROOT.parent / "shared" / "data"))
MAX_WIDTH = 900


def ratfit(*args: str, cwd: Path, ok: tuple[int, ...] = (0,)) -> None:
    """Run `python -m ratfit ARGS` in cwd; stop on an unexpected exit code."""
    cmd = [sys.executable, "-m", "ratfit", *args]
    res = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if res.returncode not in ok:
        sys.exit(f"{' '.join(args)}: exit {res.returncode}\n"
                 f"{res.stdout[-2000:]}{res.stderr[-2000:]}")


def keep(src: Path, name: str) -> None:
    """Copy a picture into docs/img, downscaled to MAX_WIDTH pixels wide."""
    from PIL import Image

    with Image.open(src) as im:
        if im.width > MAX_WIDTH:
            im = im.resize((MAX_WIDTH, round(im.height * MAX_WIDTH / im.width)),
                           Image.LANCZOS)
        im.save(IMG / name, optimize=True)
    print(f"wrote docs/img/{name}")


def addendum(tmp: Path) -> None:
    ratfit("demo", "addendum", "-o", "add", cwd=tmp)
    for name in ("figure1_function", "figure2_fits", "figure3_errors"):
        keep(tmp / "add" / f"{name}.png", f"addendum_{name}.png")


def fit_1d(tmp: Path) -> None:
    table = DATA / "tables" / "thermocouple-type-k.csv"
    ratfit("fit", str(table), "--abs-width", "0.0005", "-o", "tc.json", cwd=tmp)
    ratfit("plot", "tc.json", "--data", str(table), "-o", "tc.png", cwd=tmp)
    keep(tmp / "tc.png", "fit1d_thermocouple.png")


def cdf(tmp: Path) -> None:
    ratfit("demo", "cdf", "-o", "cdf", cwd=tmp)
    keep(tmp / "cdf" / "cdf_beckmann.png", "cdf_beckmann.png")


def batch(tmp: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (tmp / "nist.toml").write_text(
        "[defaults]\nmax_total = 30\n[[settings]]\ndt = 0.05\n[[settings]]\ndt = 0.01\n"
        f'[[inputs]]\npath = "{(DATA / "nist").as_posix()}/*.dat"\n')
    ratfit("batch", "nist.toml", "-o", "fits", "--workers", "2", cwd=tmp, ok=(0, 1))
    rows = list(csv.DictReader((tmp / "fits" / "summary.csv").open()))
    names = sorted({Path(r["input"]).stem for r in rows})
    fig, ax = plt.subplots(figsize=(7, 3.2), layout="constrained")
    for k, dt in enumerate(("0.05", "0.01")):
        tot = []
        for name in names:
            r = next(r for r in rows if Path(r["input"]).stem == name
                     and f'"dt":{dt}' in r["settings"])
            tot.append(int(r["total"]) if r["status"] == "ok" else 0)
        bars = ax.bar([i + 0.4 * k for i in range(len(names))], tot, width=0.4,
                      label=f"dt = {dt}")
        for b, t in zip(bars, tot, strict=True):
            if t == 0:
                ax.annotate("no fit ≤ 30", (b.get_x() + b.get_width() / 2, 0.5),
                            ha="center", va="bottom", rotation=90, fontsize=8)
    ax.set_xticks([i + 0.2 for i in range(len(names))], names)
    ax.set_ylabel("coefficients n + m (verified fit)")
    ax.set_title("ratfit batch on the NIST StRD files: minimal totals at two widths")
    ax.legend()
    fig.savefig(tmp / "batch.png", dpi=110)
    keep(tmp / "batch.png", "batch_nist_totals.png")


def brdf(tmp: Path) -> None:
    exr = DATA / "alta" / "data-example-01.exr"
    ratfit("brdf", "fit", str(exr), "-o", "exr.json", cwd=tmp)
    ratfit("plot", "exr.json", "--data", str(exr), "-o", "slice.png", cwd=tmp)
    keep(tmp / "slice.png", "brdf_exr_slice.png")
    ratfit("render", "exr.json", "--size", "128", "--spp", "16", "-o", "render.png", cwd=tmp)
    keep(tmp / "render.png", "brdf_exr_render.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip the BRDF pictures")
    parser.add_argument("--only", choices=["addendum", "fit_1d", "cdf", "batch", "brdf"],
                        help="make one group of pictures")
    args = parser.parse_args()
    if not DATA.is_dir():
        sys.exit(f"no data folder at {DATA} (set RATFIT_SHARED_DATA)")
    IMG.mkdir(parents=True, exist_ok=True)
    steps = [addendum, fit_1d, cdf, batch] + ([] if args.quick else [brdf])
    if args.only:
        steps = [step for step in steps + [brdf] if step.__name__ == args.only][:1]
    with tempfile.TemporaryDirectory() as tmp:
        for step in steps:
            t0 = time.perf_counter()
            step(Path(tmp))
            print(f"{step.__name__}: {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
