"""Renders of the Cornell materials: the default rational fit and the better analytic model,
each against the measured data, in the same Mitsuba 3 scene.

For each material of ``--data``/cornell (garnet_red, acryl_blue, cayman, krylon_blue,
mystique):

* the default rational fit, ``--fits DIR/<material>.json`` (what ``ratfit brdf fit DATA
  -o DIR/<material>.json`` writes). A missing one is made there with
  :func:`ratfit.jobs.fit_brdf_file` (the job behind ``ratfit brdf fit``), one material at
  a time, each in a child process: one that has not finished in ``--fit-timeout``
  minutes is stopped and made again with ``--work-limit`` QP solves per channel, and the
  table says so. A fit given in ``--fits`` that its command made with ``--work-limit``
  says so too;
* lambert+ggx and lambert+ggx*2 fitted to the data with
  :func:`ratfit.viz.report.model_fit_for` (what ``ratfit brdf model`` fits, ``--starts``
  8). The model drawn is the one with the smaller cos-weighted RMSE at the samples (RMS
  of the channels' cos_rmse, as ``ratfit brdf compare`` computes it): chosen before any
  render, from the data alone.

The fit and the model are each rendered by :func:`ratfit.jobs.render_fit` (what ``ratfit
render FIT.json --data DATA`` does) beside the data, in each ``--scene``, with the same
camera, light, samples and seed. Image errors over the sphere's pixels:

* rel. RMSE: RMS of the RGB difference from the data's render / RMS of the data's render
  (what ``ratfit render`` reports);
* lum. ratio: mean luminance of the render / mean luminance of the data's render;
* chroma: the distance between the (r, g) chromaticities, (r, g) / (r + g + b), of the
  two renders per pixel, averaged with the data render's luminance as the weight (0: the
  same colour everywhere; pure red against pure green is 1.41);
* SMAPE: the mean over the sphere's pixels and R, G, B of |x - d| / (|x| + |d| + e), e
  1 % of the data render's mean (0: the same image, 1: black or far off everywhere). The
  rel. RMSE is decided by the brightest pixels (a black sphere scores 1.0, a right one
  whose highlight is a few pixels off more); SMAPE weighs every pixel alike.

The fit wins a material (in a scene) when its rel. RMSE is the smaller; the SMAPE count
is given beside it. Each material
and scene also gets a PNG in ``--out``: data | fit | model | |fit - data| | |model -
data|, one exposure (the brightest of the three renders' 99.5th luminance percentile
maps to 1, as in ``ratfit render``). With ``--markdown`` the same panels, one row per
material, go beside the Markdown file, one picture per scene.

Run:  nice -n 10 python benchmarks/bench_cornell_render.py [--fits DIR] [--out DIR]
      [--scene sphere [point ...]] [--size 128] [--spp 64] [--only NAME]
      [--work-limit 1000] [--fit-timeout 20] [--data-root ../shared/data]
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

REPO = Path(__file__).resolve().parents[1]
MATERIALS = ("garnet_red", "acryl_blue", "cayman", "krylon_blue", "mystique")
MODELS = ("lambert+ggx", "lambert+ggx*2")
SCENES = ("sphere", "sky", "point", "sphere-point", "furnace")
PANELS = ("data", "fit", "model", "|fit - data|", "|model - data|")


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------
# the default rational fits


def _fit_child(data: str, out: str, work_limit: int | None) -> None:
    """One default fit (``work_limit``: QP solves per channel instead of the default), in
    a child process: exit 0 when the fit file is written."""
    from ratfit.brdf.options import BRDFOptions
    from ratfit.jobs import BRDFFitRequest, fit_brdf_file

    opts = BRDFOptions() if work_limit is None else BRDFOptions.from_params(
        {"work_limit": work_limit})
    # the fit file's provenance records the command that gives the same fit
    sys.argv = ["ratfit", "brdf", "fit", data, "-o", out,
                *([] if work_limit is None else ["--work-limit", str(work_limit)])]
    rep = fit_brdf_file(BRDFFitRequest(Path(data), options=opts, output=Path(out)))
    for line in [*rep.notes(), rep.hint()]:
        if line:
            say(f"  {line}")
    sys.exit(0 if rep.written is not None else 1)


def _run_fit(data: Path, out: Path, work_limit: int | None, timeout: float | None
             ) -> tuple[bool, float]:
    """(finished, seconds) of one fit in a child process, stopped after ``timeout``."""
    ctx = multiprocessing.get_context("fork")  # before Mitsuba is loaded: fork is safe
    proc = ctx.Process(target=_fit_child, args=(str(data), str(out), work_limit))
    t0 = time.perf_counter()
    proc.start()
    proc.join(timeout)
    if proc.is_alive():
        proc.kill()
        proc.join()
        return False, time.perf_counter() - t0
    return True, time.perf_counter() - t0


def given_work_limit(path: Path) -> int | None:
    """The ``--work-limit`` of the command that wrote a fit file, if it had one."""
    from ratfit.io.fitfile import load_fit

    return work_limit_of((load_fit(path).provenance or {}).get("command") or [])


def work_limit_of(cmd: list[str]) -> int | None:
    """The ``--work-limit`` value of a command line, or None."""
    for i, arg in enumerate(cmd):
        if arg == "--work-limit" and i + 1 < len(cmd):
            return int(cmd[i + 1])
        if arg.startswith("--work-limit="):
            return int(arg.split("=", 1)[1])
    return None


def ensure_fit(name: str, data: Path, fits: Path, work_limit: int,
               timeout_min: float) -> tuple[Path | None, str, int | None]:
    """The fit file of ``name``, how it was made (for the table) and its work limit
    (None: the default)."""
    path = fits / f"{name}.json"
    if path.exists():
        wl = given_work_limit(path)
        return path, "given" + (f", --work-limit {wl}" if wl is not None else ""), wl
    fits.mkdir(parents=True, exist_ok=True)
    say(f"{name}: no {path}; making the default fit (ratfit brdf fit {data} -o {path}), "
        f"stopped after {timeout_min:g} min")
    done, secs = _run_fit(data, path, None, 60.0 * timeout_min)
    if done:
        say(f"{name}: default fit {'written' if path.exists() else 'NOT verified'}, "
            f"{secs:.0f} s")
        return (path, f"made here, {secs:.0f} s", None) if path.exists() else \
            (None, f"no verified default fit ({secs:.0f} s)", None)
    say(f"{name}: the default fit has not finished in {timeout_min:g} min; fitting again "
        f"with --work-limit {work_limit}")
    done, secs2 = _run_fit(data, path, work_limit, None)
    how = (f"--work-limit {work_limit} (default fit stopped after {timeout_min:g} min), "
           f"made here, {secs2:.0f} s")
    if not path.exists():
        return None, f"no verified fit with --work-limit {work_limit} ({secs2:.0f} s)", None
    say(f"{name}: {how}")
    return path, how, work_limit


# ---------------------------------------------------------------------------------------
# the analytic models and the errors at the samples


@dataclass
class Material:
    name: str
    data: Path
    fit: Path | None
    fit_how: str
    work_limit: int | None = None  # the fit's, when not the default
    fit_coefs: int | None = None
    fit_param: str = ""
    fit_cos: float | None = None
    model_cos: dict[str, float] = field(default_factory=dict)
    model_params: dict[str, int] = field(default_factory=dict)
    model_file: dict[str, Path] = field(default_factory=dict)
    model_seconds: float = 0.0
    best: str = ""
    fit_diffuse: np.ndarray | None = None  # median fit / data per channel, diffuse samples
    model_diffuse: dict[str, np.ndarray] = field(default_factory=dict)


def rgb_text(v: np.ndarray) -> str:
    return " / ".join(f"{x:.3g}" for x in v)


def channel_rms(rows: list[dict[str, Any]], key: str) -> float:
    """RMS over the channels of one metric."""
    return float(np.sqrt(np.mean([r[key] ** 2 for r in rows])))


DIFFUSE = 0.05  # samples below this fraction of their channel's largest value
EPS = 1e-3  # 1/sr added to both sides of a ratio (measured zeros)


def diffuse_ratio(pred: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per channel, the median of (pred + EPS) / (y + EPS) over the samples below
    ``DIFFUSE`` x the channel's largest value: how bright a fit is off the highlight."""
    out = []
    for c in range(y.shape[1]):
        low = y[:, c] < DIFFUSE * y[:, c].max()
        out.append(float(np.median((pred[low, c] + EPS) / (y[low, c] + EPS))))
    return np.array(out)


def fit_models(m: Material, out: Path, starts: int) -> None:
    """Both models fitted to the data and saved; the one with the smaller cos RMSE is
    ``m.best``. The rational fit's own errors at the samples beside them."""
    from ratfit.brdf.io import brdf_dataset
    from ratfit.viz.report import (
        LoadedFit,
        data_dirs,
        load_data_for,
        model_fit_for,
        model_metrics,
        rational_metrics,
    )

    if m.fit is not None:
        lf = LoadedFit.load(m.fit)
        dsf = load_data_for(lf, m.data)
        rows = rational_metrics(lf, dsf)
        m.fit_cos = channel_rms(rows, "cos_rmse")
        m.fit_coefs = sum(int(r["coefficients"]) for r in rows)
        m.fit_param = str(lf.param)
        m.fit_diffuse = diffuse_ratio(lf.brdf.eval_coords(dsf.x), np.asarray(dsf.y))
    ds = brdf_dataset(m.data, None, color="rgb")
    param = str(ds.meta.get("param_in"))
    L, V = data_dirs(param, ds)
    t0 = time.perf_counter()
    for spec in MODELS:
        mf = model_fit_for(param, ds, spec, starts=starts)
        mf.info["data"] = str(m.data)
        path = out / "models" / f"{m.name}-{spec.replace('*', 'x')}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        mf.save(path)
        rows = model_metrics(mf, param, ds)
        m.model_cos[spec] = channel_rms(rows, "cos_rmse")
        m.model_params[spec] = int(mf.params.size)
        m.model_file[spec] = path
        m.model_diffuse[spec] = diffuse_ratio(mf.eval_dirs(L, V), np.asarray(ds.y))
    m.model_seconds = time.perf_counter() - t0
    m.best = min(MODELS, key=lambda s: m.model_cos[s])
    say(f"{m.name}: models fitted in {m.model_seconds:.0f} s; cos RMSE "
        + ", ".join(f"{s} {v:.4g}" for s, v in m.model_cos.items())
        + (f", rational {m.fit_cos:.4g}" if m.fit_cos is not None else "")
        + f": {m.best} drawn")


# ---------------------------------------------------------------------------------------
# renders and image errors


def chroma_distance(a: np.ndarray, b: np.ndarray, weight: np.ndarray) -> float:
    """Weighted mean distance of the (r, g) chromaticities of two (N, 3) sets of pixels
    (a pixel with r + g + b = 0 counts as neutral, (1/3, 1/3))."""

    def rg(x: np.ndarray) -> np.ndarray:
        s = x.sum(axis=1, keepdims=True)
        return np.where(s > 0, x[:, :2] / np.where(s > 0, s, 1.0), 1.0 / 3.0)

    d = np.linalg.norm(rg(a) - rg(b), axis=1)
    w = np.maximum(weight, 0.0)
    return float((d * w).sum() / w.sum())


@dataclass
class Render:
    """A render of one material (fit or model) and the data's, from one render_fit call."""

    image: np.ndarray
    data: np.ndarray
    rel_rmse: float
    lum_ratio: float
    chroma: float
    smape: float
    seconds: dict[str, float]


def smape(a: np.ndarray, b: np.ndarray) -> float:
    """Mean of |a - b| / (|a| + |b| + e) over (N, 3) pixels, e 1 % of ``b``'s mean (b: the
    data's render)."""
    e = 0.01 * float(np.mean(np.abs(b)))
    return float(np.mean(np.abs(a - b) / (np.abs(a) + np.abs(b) + e)))


def render_pair(fit_file: Path, data: Path, out: Path, scene: str, size: int, spp: int,
                seed: int) -> Render:
    """``ratfit render fit_file --data data`` (as a library call) into an EXR; the two
    renders read back, with the image errors."""
    from ratfit.jobs import RenderRequest, render_fit
    from ratfit.jobs.render import LUMA
    from ratfit.render import mitsuba_bsdf as mb
    from ratfit.render.scene import sphere_view

    out.parent.mkdir(parents=True, exist_ok=True)
    rep = render_fit(RenderRequest(fit_file, out, scene=scene, spp=spp, size=size, data=data,
                                   seed=seed, progress=lambda s: None))
    mi, _ = mb._import_mitsuba()
    both = np.asarray(mi.Bitmap(str(out)), dtype=np.float64)[..., :3]
    gap = max(2, size // 64)  # render_fit's layout: fit | gap | data | gap | |diff|
    img, dimg = both[:, :size], both[:, size + gap:2 * size + gap]
    hit, _ = sphere_view(size)
    d = rep.difference
    assert d is not None
    # the EXR (float32) against the job's own numbers (float64)
    mine = np.sqrt(np.mean((img[hit] - dimg[hit]) ** 2)) / np.sqrt(np.mean(dimg[hit] ** 2))
    if abs(mine - d["rel_rmse"]) > 1e-4 * max(1.0, d["rel_rmse"]):
        raise RuntimeError(f"{out}: rel. RMSE of the EXR {mine:.6g} != the job's "
                           f"{d['rel_rmse']:.6g}")
    return Render(img, dimg, float(d["rel_rmse"]),
                  float(d["mean_luminance_fit"] / d["mean_luminance_data"]),
                  chroma_distance(img[hit], dimg[hit], dimg[hit] @ LUMA),
                  smape(img[hit], dimg[hit]), dict(rep.seconds))


def panels(data: np.ndarray, fit: np.ndarray | None, model: np.ndarray, size: int
           ) -> tuple[list[np.ndarray], float]:
    """The five panels, tonemapped with one exposure, and that exposure."""
    from ratfit.jobs.render import LUMA, _tonemap
    from ratfit.render.scene import sphere_view

    hit, _ = sphere_view(size)
    shown = [im for im in (data, fit, model) if im is not None]
    top = max(float(np.quantile(im[hit] @ LUMA, 0.995)) for im in shown)
    scale = 1.0 / max(top, 1e-12)
    blank = np.zeros_like(data)
    linear = [data, blank if fit is None else fit, model,
              blank if fit is None else np.abs(fit - data), np.abs(model - data)]
    return [_tonemap(im, scale) for im in linear], scale


def draw_rows(rows: list[tuple[str, list[np.ndarray], list[str]]], title: str) -> Any:
    """A figure of rows of five labelled panels (``rows``: label, panels, captions)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    size = rows[0][1][0].shape[0]
    inch = max(size, 160) / 100.0
    fig, axes = plt.subplots(len(rows), len(PANELS), squeeze=False,
                             figsize=(len(PANELS) * inch, len(rows) * (inch + 0.45) + 0.35))
    for r, (label, ims, captions) in enumerate(rows):
        for c, (ax, im) in enumerate(zip(axes[r], ims, strict=True)):
            ax.imshow(im, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(captions[c], fontsize=7)
            if c == 0:
                ax.set_ylabel(label, fontsize=8)
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------------------


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data-root", type=Path, default=REPO.parent / "shared" / "data",
                    help="folder holding cornell/<material>.brdf")
    default_out = Path(tempfile.gettempdir()) / "ratfit-cornell-render"
    ap.add_argument("--out", type=Path, default=default_out,
                    help=f"PNGs, EXRs and model files (default {default_out})")
    ap.add_argument("--fits", type=Path, help="<material>.json default fits; missing ones "
                    "are made there (default OUT/fits)")
    ap.add_argument("--scene", nargs="+", choices=SCENES, default=["sphere"])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--starts", type=int, default=8, help="model fit starts per channel")
    ap.add_argument("--only", nargs="+", metavar="NAME",
                    help="run the materials whose name contains one of these")
    ap.add_argument("--work-limit", type=int, default=1000,
                    help="QP solves per channel of a fit made again after its default fit "
                         "ran past --fit-timeout")
    ap.add_argument("--fit-timeout", type=float, default=20.0,
                    help="minutes a default fit made here may take")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    fits = args.fits or args.out / "fits"
    names = [n for n in MATERIALS if not args.only or any(o in n for o in args.only)]
    if not names:
        ap.error(f"no material matches --only {args.only!r}")
    steps: list[str] = []

    # 1. fits, one at a time, before Mitsuba is loaded (the fits run in forked children)
    mats = []
    for name in names:
        data = args.data_root / "cornell" / f"{name}.brdf"
        t0 = time.perf_counter()
        path, how, wl = ensure_fit(name, data, fits, args.work_limit, args.fit_timeout)
        steps.append(f"{name} rational fit: {how} ({time.perf_counter() - t0:.0f} s here)")
        mats.append(Material(name, data, path, how, wl))

    # 2. models, chosen by their cos RMSE at the samples
    for m in mats:
        fit_models(m, args.out, args.starts)
        steps.append(f"{m.name} models: {m.model_seconds:.0f} s")
    rep.table(
        "the default rational fit and the analytic models at the samples (cos RMSE: RMS "
        "over R, G, B of each channel's cos-weighted RMSE, 1/sr)",
        ["material", "fit", "frame", "fit n+m", "fit cos RMSE",
         *(f"{s} cos RMSE" for s in MODELS), "drawn", "diffuse fit / data",
         "diffuse model / data"],
        [[m.name, m.fit_how, m.fit_param or "-",
          "-" if m.fit_coefs is None else str(m.fit_coefs),
          "-" if m.fit_cos is None else f"{m.fit_cos:.4g}",
          *(f"{m.model_cos[s]:.4g}" for s in MODELS), m.best,
          "-" if m.fit_diffuse is None else rgb_text(m.fit_diffuse),
          rgb_text(m.model_diffuse[m.best])] for m in mats],
        note=f"The model drawn is the one with the smaller cos RMSE ({', '.join(MODELS)}, "
             f"{args.starts} starts per channel, fitted by `ratfit.viz.report.model_fit_for`: "
             "`ratfit brdf model`); n+m: the rational fit's coefficients over the three "
             "channels; diffuse x / data: per channel (R / G / B), the median of (x + 1e-3) / "
             f"(data + 1e-3) over the samples below {DIFFUSE:g} x the channel's largest value "
             "(1: right off the highlight).")

    # 3. renders
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    args.out.mkdir(parents=True, exist_ok=True)
    for scene in args.scene:
        rows, pics, wins, counted, smape_wins = [], [], 0, 0, 0
        same_data = 0.0
        for m in mats:
            stem = args.out / "exr" / f"{m.name}-{scene}"
            t0 = time.perf_counter()
            fr = None if m.fit is None else render_pair(
                m.fit, m.data, stem.with_name(stem.name + "-fit.exr"), scene, args.size,
                args.spp, args.seed)
            mr = render_pair(m.model_file[m.best], m.data,
                             stem.with_name(stem.name + "-model.exr"), scene, args.size,
                             args.spp, args.seed)
            secs = time.perf_counter() - t0
            if fr is not None:  # the data's render is the same in both calls (same seed)
                same_data = max(same_data, float(np.abs(fr.data - mr.data).max()))
            win = fr is not None and fr.rel_rmse < mr.rel_rmse
            wins += win
            smape_wins += fr is not None and fr.smape < mr.smape
            counted += 1
            nparams = m.model_params[m.best]
            rows.append([
                m.name + ("" if m.work_limit is None else f" (fit: --work-limit {m.work_limit})"),
                "-" if m.fit_coefs is None else str(m.fit_coefs),
                f"{m.best} ({nparams})",
                "-" if fr is None else f"{fr.rel_rmse:.4f}", f"{mr.rel_rmse:.4f}",
                "-" if fr is None else f"{fr.lum_ratio:.3f}", f"{mr.lum_ratio:.3f}",
                "-" if fr is None else f"{fr.chroma:.4f}", f"{mr.chroma:.4f}",
                "-" if fr is None else f"{fr.smape:.4f}", f"{mr.smape:.4f}",
                "fit" if win else "model" + (" (no verified fit)" if fr is None else "")])
            ims, scale = panels(mr.data, None if fr is None else fr.image, mr.image, args.size)
            caps = ["data",
                    "no fit" if fr is None else f"fit ({m.fit_coefs} coefs)\nrel. RMSE "
                                                f"{fr.rel_rmse:.3f}",
                    f"{m.best} ({nparams})\nrel. RMSE {mr.rel_rmse:.3f}",
                    "|fit - data|", "|model - data|"]
            title = (f"{m.name}, {scene}, {args.size}x{args.size}, {args.spp} spp, seed "
                     f"{args.seed}; one exposure x{scale:.3g}")
            fig = draw_rows([(m.name, ims, caps)], title)
            png = args.out / f"{m.name}-{scene}.png"
            fig.savefig(png, dpi=100, metadata={"Software": None})
            plt.close(fig)
            pics.append((m.name, ims, caps))
            timing = ", ".join(f"{k} {v:.0f} s" for k, v in
                               ({} if fr is None else fr.seconds).items())
            steps.append(f"{m.name} {scene}: renders {secs:.0f} s (fit call: {timing}); "
                         f"wrote {png}")
            say(steps[-1])
        rep.table(
            f"{scene} scene, {args.size}x{args.size}, {args.spp} spp, seed {args.seed}: "
            "image errors against the data's render over the sphere's pixels",
            ["material", "fit n+m", "model (params)", "rel. RMSE fit", "rel. RMSE model",
             "lum. ratio fit", "lum. ratio model", "chroma fit", "chroma model",
             "SMAPE fit", "SMAPE model", "smaller rel. RMSE"], rows,
            note=f"fit wins {wins} of {counted} ({scene}); its SMAPE is the smaller in "
                 f"{smape_wins} of {counted}. rel. RMSE: RMS of the RGB "
                 "difference / RMS of the data's render; lum. ratio: mean luminance / the "
                 "data's; chroma: luminance-weighted mean distance of the (r, g) "
                 "chromaticities; SMAPE: mean of |x - d| / (|x| + |d| + 1 % of the data's "
                 "mean) over pixels and channels. The data's render in the fit's and in "
                 "the model's call "
                 f"differ by at most {same_data:.3g} (same seed).")
        fig = draw_rows(pics, f"{scene}, {args.size}x{args.size}, {args.spp} spp: data | "
                              "fit | model | |fit - data| | |model - data|, one exposure "
                              "per row")
        rep.figure(fig, f"{rep.stem('bench_cornell_render')}_{scene}",
                   f"{scene}: data, fit, model and the two differences per material", fmt="jpg")
        plt.close(fig)
    say("\nsteps:")
    for s in steps:
        say(f"  {s}")
    rep.write()


if __name__ == "__main__":
    main()
