"""Code export: the generated C (compiled with gcc), Python (exec'd) and GLSL (validated by
glslangValidator) reproduce the saved fit; bad or unverified fit files are refused."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import need_tool

from ratfit.brdf.fitter import BRDFFit
from ratfit.brdf.parametrizations import PARAMETRIZATIONS, get_parametrization
from ratfit.cli import main
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.export import code as code_mod
from ratfit.export.code import SUPPORTED_PARAMETRIZATIONS, export_source, plan_forms
from ratfit.io.fitfile import parse_fit, save_fit

RTOL = 1e-12
DRIVER = r"""
#include <stdio.h>
int main(void)
{
    double x[NIN], out[RATFIT_NCHANNELS];
    for (;;) {
        for (int i = 0; i < NIN; ++i)
            if (scanf("%lf", &x[i]) != 1) return 0;
        CALL;
        for (int j = 0; j < RATFIT_NCHANNELS; ++j) printf("%.17g ", out[j]);
        printf("\n");
    }
}
"""


def _fit(x, y, extra=None, *, n=4, m=3, basis="legendre", domain=None):
    """A saved fit built by linearised least squares (p - y q = 0, q_0 = 1).

    Export does not care how coefficients were found; building them here keeps these
    tests independent of the QP search.
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    Y = np.asarray(y, dtype=float).reshape(len(x), -1)
    dom = np.column_stack([x.min(axis=0), x.max(axis=0)]) if domain is None else domain
    space = PolynomialSpace(basis, dom)
    Dp, Dq = space.design(x, n), space.design(x, m)
    chans = []
    for j in range(Y.shape[1]):
        A = np.hstack([Dp, -Y[:, j:j + 1] * Dq[:, 1:]])
        c = np.linalg.lstsq(A, Y[:, j] * Dq[:, 0], rcond=None)[0]
        p, q = c[:n], np.concatenate([[1.0], c[n:]])
        rf = RationalFunction(space, p, q)
        assert np.all(rf.denominator(x) > 0)
        chans.append({"name": f"y{j}", "p": p.tolist(), "q": q.tolist(),
                      "diagnostics": {"verified": True, "linf": float(np.max(np.abs(
                          rf(x) - Y[:, j])))}, "monomial": None})
    doc = {"format": "ratfit.fit", "version": 1, "space": space.to_dict(), "channels": chans,
           "provenance": {}}
    doc.update(extra or {})
    return parse_fit(json.loads(json.dumps(doc)))


@pytest.fixture(scope="module")
def fits():
    rng = np.random.default_rng(0)
    x1 = np.linspace(0.0, 3.0, 120)[:, None]
    y1 = np.column_stack([1 / (1 + x1[:, 0] ** 2) + 0.5, np.exp(-x1[:, 0]) + 1])
    # a shifted domain and a higher degree: the monomial form in x loses digits
    xs = np.linspace(20.0, 30.0, 150)[:, None]
    ys = np.exp(np.sin(xs[:, 0])) + 3.0
    x2 = rng.uniform(0.0, 1.0, (300, 2))
    y2 = (1 + x2[:, 0] * x2[:, 1]) / (2 + x2[:, 0] ** 2 + np.sin(x2[:, 1]))
    return {
        "1d": _fit(x1, y1),
        "shifted": _fit(xs, ys, n=9, m=6, basis="chebyshev"),
        "2d": _fit(x2, y2, n=10, m=6),
        # fits from the search, held in data-orthonormal (Arnoldi) bases
        "seed": _searched(np.linspace(-3, 12, 500)[:, None], 0.01, min_total=34),
        "arn2d": _searched(x2, 0.01, y=y2),
    }


def _searched(x, dt, y=None, **params):
    from ratfit.core.segments import Segments
    from ratfit.demos.addendum import addendum_function
    from ratfit.fitting.search import RationalFitter
    from ratfit.io.fitfile import fit_document

    y = addendum_function(x[:, 0]) if y is None else y
    res = RationalFitter(**params).fit(Segments.from_relative(x, y, dt)).results_
    assert all(r.success for r in res) and res[0].rational.orthonormal
    return parse_fit(json.loads(json.dumps(fit_document(res))))


def _run_c(tmp_path: Path, text: str, nin: int, call: str, pts: np.ndarray) -> np.ndarray:
    need_tool("gcc", "the exported C code is compiled and run with it")
    src = tmp_path / "f.c"
    src.write_text(text + DRIVER.replace("NIN", str(nin)).replace("CALL", call))
    exe = tmp_path / "f"
    subprocess.run(["gcc", "-std=c99", "-O2", "-Wall", "-Werror", "-o", str(exe), str(src),
                    "-lm"], check=True, capture_output=True)
    inp = "\n".join(" ".join(repr(float(v)) for v in p) for p in pts)
    out = subprocess.run([str(exe)], input=inp, capture_output=True, text=True, check=True)
    return np.array([[float(v) for v in ln.split()] for ln in out.stdout.strip().splitlines()])


def _points(saved, n=400, seed=1):
    dom = saved.space.domain
    rng = np.random.default_rng(seed)
    return dom[:, 0] + (dom[:, 1] - dom[:, 0]) * rng.random((n, dom.shape[0]))


def _close(got, ref):
    scale = np.max(np.abs(ref))
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=RTOL * scale * 1e-2)


@pytest.mark.slow
def test_auto_form_choice(fits):
    assert [f.form for f in plan_forms(fits["1d"])] == ["horner", "horner"]
    (f,) = plan_forms(fits["shifted"])
    assert f.form == "clenshaw" and f.family == "chebyshev"
    assert f.monomial_rel_diff > 1e-13  # the reason it was not Horner
    text = export_source(fits["shifted"], "c").text
    assert "clenshaw" in text and "monomial conversion loses accuracy" in text


CASES = [(n, f) for n in ("1d", "shifted", "2d") for f in ("auto", "clenshaw", "horner")
         if (n, f) != ("shifted", "horner")]
CASES += [("seed", "auto"), ("seed", "recurrence"), ("arn2d", "auto"), ("arn2d", "recurrence")]


@pytest.mark.slow
def test_arnoldi_fit_exports_its_recurrence_when_conversions_lose_digits(fits):
    (f,) = plan_forms(fits["seed"])
    assert f.form == "recurrence"  # +-1 % seed fit: Legendre conversion loses ~1e-5
    assert "conversions lose accuracy" in f.reason


@pytest.mark.parametrize("name,form", CASES)
@pytest.mark.slow
def test_c_matches_python(fits, tmp_path, name, form):
    saved = fits[name]
    res = export_source(saved, "c", form=form)
    pts = _points(saved)
    got = _run_c(tmp_path, res.text, saved.space.dim, "ratfit_eval(x, out)", pts)
    _close(got, saved(pts))


@pytest.mark.parametrize("name", ["1d", "shifted", "2d", "seed", "arn2d"])
def test_python_export_matches(fits, name):
    saved = fits[name]
    ns: dict = {}
    exec(compile(export_source(saved, "python").text, "export", "exec"), ns)
    pts = _points(saved, 200)
    got = np.array([ns["ratfit_eval"](list(p)) for p in pts])
    _close(got, saved(pts))


def test_forced_horner_loses_accuracy_where_auto_refuses_it(fits, tmp_path):
    saved = fits["shifted"]
    res = export_source(saved, "c", form="horner")
    assert "ABOVE" in res.text  # the exporter says the forced form misses the target
    pts = _points(saved)
    got = _run_c(tmp_path, res.text, 1, "ratfit_eval(x, out)", pts)
    ref = saved(pts)
    assert np.max(np.abs(got - ref)) > RTOL * np.max(np.abs(ref))


@pytest.mark.parametrize("name,form", [("1d", "clenshaw"), ("2d", "clenshaw"),
                                       ("seed", "recurrence"), ("arn2d", "recurrence")])
def test_glsl_validates(fits, tmp_path, name, form):
    need_tool("glslangValidator", "the exported GLSL is validated with it (Debian/Ubuntu: "
              "apt-get install glslang-tools; .ci/run installs it)")
    frag = tmp_path / "f.frag"
    body = export_source(fits[name], "glsl", form=form).text
    frag.write_text("#version 330 core\n" + body + """
out vec4 color;
void main()
{
    float x[RATFIT_DIM];
    float r[RATFIT_NCHANNELS];
    for (int i = 0; i < RATFIT_DIM; ++i) x[i] = gl_FragCoord.x / 100.0;
    ratfit_eval(x, r);
    color = vec4(r[0]);
}
""")
    out = subprocess.run(["glslangValidator", str(frag)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def _brdf_saved(param="RUSIN_TH_TD", cosine=False, fold=False):
    rng = np.random.default_rng(3)
    p = get_parametrization(param)
    L = _dirs(rng, 600)
    V = _dirs(rng, 600)
    x = p.from_dirs(L, V)
    y = 0.2 + 0.5 * np.cos(x[:, 0]) ** 2 + 0.1 * x[:, 1]
    saved = _fit(x, y, extra={"brdf": {"parametrization": p.name, "cosine_weighted": cosine,
                                       "fold_phi_d": fold}}, n=10, m=1)
    return BRDFFit(saved, p.name, cosine, fold)


def _dirs(rng, n):
    ct = rng.uniform(0.05, 1.0, n)
    ph = rng.uniform(-np.pi, np.pi, n)
    st = np.sqrt(1 - ct**2)
    return np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=1)


@pytest.mark.parametrize("param,cosine", [("RUSIN_TH_TD", True),
                                          ("ISOTROPIC_TL_TV_PROJ_DPHI", False)])
def test_c_brdf_from_directions(tmp_path, param, cosine):
    bf = _brdf_saved(param, cosine)
    res = export_source(bf.saved, "c", parametrization=param, cosine_weighted=cosine)
    rng = np.random.default_rng(9)
    L, V = _dirs(rng, 300), _dirs(rng, 300)
    x = get_parametrization(param).from_dirs(L, V)
    dom = bf.saved.space.domain
    keep = np.all((x >= dom[:, 0]) & (x <= dom[:, 1]), axis=1)
    L, V = L[keep], V[keep]
    got = _run_c(tmp_path, res.text.replace("const double V[3]", "const double *V")
                 .replace("const double L[3]", "const double *L"), 6,
                 "ratfit_brdf(x, x + 3, out)", np.hstack([L, V]))
    _close(got, bf.eval_dirs(L, V))


def test_every_parametrization_in_exported_python():
    """The exported coordinate code equals ratfit.brdf.parametrizations for all parametrizations."""
    assert set(SUPPORTED_PARAMETRIZATIONS) == set(PARAMETRIZATIONS)
    rng = np.random.default_rng(5)
    L, V = _dirs(rng, 60), _dirs(rng, 60)
    for name, par in PARAMETRIZATIONS.items():
        x = par.from_dirs(L, V)
        saved = _fit(x, 1.0 + 0.1 * x[:, 0], n=2, m=1)
        ns: dict = {}
        exec(compile(export_source(saved, "python", parametrization=name).text, name, "exec"),
             ns)
        got = np.array([ns["ratfit_coords"](list(a), list(b)) for a, b in zip(L, V, strict=True)])
        np.testing.assert_allclose(got, x, rtol=1e-12, atol=1e-12, err_msg=name)


def test_cli_export_and_bad_inputs(fits, tmp_path):
    runner = CliRunner()
    good = tmp_path / "fit.json"
    save_fit(good, fit_document_from(fits["2d"]))
    out = tmp_path / "f.c"
    r = runner.invoke(main, ["export", str(good), "--lang", "c", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "channel y0: horner" in r.output and out.is_file()
    # unverified fit: refused, nothing written
    doc = json.loads(good.read_text())
    doc["channels"][0]["diagnostics"]["verified"] = False
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    out2 = tmp_path / "sub" / "g.c"
    r = runner.invoke(main, ["export", str(bad), "--lang", "c", "-o", str(out2)])
    assert r.exit_code == 2 and "unverified" in r.output and not out2.exists()
    junk = tmp_path / "junk.json"
    junk.write_text("{not json")
    r = runner.invoke(main, ["export", str(junk), "--lang", "python", "-o", str(out2)])
    assert r.exit_code == 2 and "error:" in r.output and not out2.exists()
    r = runner.invoke(main, ["export", str(tmp_path / "none.json"), "--lang", "glsl", "-o",
                             str(out2)])
    assert r.exit_code == 2 and not out2.exists()
    r = runner.invoke(main, ["export", str(good), "--lang", "c", "--prefix", "1x", "-o",
                             str(out2)])
    assert r.exit_code == 2 and "prefix" in r.output and not out2.exists()


def fit_document_from(saved):
    """A fit document with the saved coefficients and a verified flag per channel."""
    return {
        "format": "ratfit.fit", "version": 1, "space": saved.space.to_dict(),
        "channels": [{"name": c.name, "p": c.rational.p.tolist(), "q": c.rational.q.tolist(),
                      "diagnostics": dict(c.summary), "monomial": None}
                     for c in saved.channels],
        "provenance": {},
    }


# ---------------------------------------------------------------------------- injection
# Each payload ends a one-line comment in at least one language (newline, lone CR, a C/GLSL
# line splice, Unicode line breaks, a trigraph splice, a block-comment end) and then runs
# code if it is read as code.
_PAYLOADS = [
    "fit\nimport os; open('PWNED', 'w').write('x')\n#",
    "fit\rimport os; open('PWNED', 'w').write('x')\r#",
    "fit\\\n__attribute__((constructor)) static void pw(void){fopen(\"PWNED\",\"w\");}\n//",
    "fit ??/\nint pwned = 1;",
    "fit\u2028import os\u2029#\x0b\x0c\x85*/ #error injected",
    "fit\n#error injected\n",
]


@pytest.mark.parametrize("lang", ["python", "c", "glsl"])
@pytest.mark.slow
def test_text_from_a_fit_file_never_becomes_code(fits, tmp_path, monkeypatch, lang):
    """Hostile file and channel names reach the generated source only as inert text: the
    source compiles, every comment line stays one line, and running it evaluates the fit and
    does nothing else (no PWNED file, no extra top-level statement)."""
    import ast
    import importlib.util

    monkeypatch.chdir(tmp_path)
    saved = fits["1d"]
    doc = fit_document_from(saved)
    for j, ch in enumerate(doc["channels"]):
        ch["name"] = _PAYLOADS[j % len(_PAYLOADS)] + f"{j}"
    runner = CliRunner()
    for k, payload in enumerate(_PAYLOADS):
        name = payload.replace("/", "|") + ".json"  # a file name cannot hold "/"
        try:
            fit_path = tmp_path / name
            save_fit(fit_path, doc)
        except (OSError, ValueError):
            continue
        out = tmp_path / f"out{k}.{ {'python': 'py', 'c': 'c', 'glsl': 'glsl'}[lang] }"
        r = runner.invoke(main, ["export", str(fit_path), "--lang", lang, "-o", str(out)])
        assert r.exit_code == 0, r.output
        text = out.read_text(encoding="ascii")  # every byte is ASCII
        assert "\r" not in text and "\\\n" not in text and "??/" not in text
        head = text.split("\n\n")[0].split("\n")
        cm = "#" if lang == "python" else "//"
        assert all(ln.startswith(cm + " ") for ln in head), head
        assert "PWNED" not in "".join(ln for ln in text.splitlines()  # but as a string
                                      if not ln.lstrip().startswith((cm, "CHANNELS = ")))
        directives = [ln for ln in text.splitlines() if ln.lstrip().startswith("#")
                      and lang != "python"]
        fixed = {ln.strip() for ln in code_mod._C_EXACT}  # the exactness guard, verbatim
        assert all(d.startswith(("#define RATFIT_", "#include <math.h>")) or d.strip() in fixed
                   for d in directives)
        if lang == "python":
            tree = ast.parse(text)
            kinds = {type(n).__name__ for n in tree.body}
            assert kinds <= {"Expr", "Import", "Assign", "FunctionDef"}, kinds
            spec = importlib.util.spec_from_file_location(f"exported{k}", out)
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
            assert mod.CHANNELS == tuple(c["name"] for c in doc["channels"])
            x = 1.3
            ref = saved.channels[0].rational(np.array([[x]]))[0]
            assert mod.ratfit_eval([x])[0] == pytest.approx(ref, rel=1e-12)
        elif lang == "c":
            pts = _points(saved, n=5)
            got = _run_c(tmp_path, text, 1, "ratfit_eval(x, out)", pts)
            ref = np.column_stack([c.rational(pts) for c in saved.channels])
            _close(got, ref)
        else:
            need_tool("glslangValidator", "the exported GLSL is validated with it")
            shader = tmp_path / f"s{k}.frag"
            shader.write_text("#version 330\n" + text + "out vec4 color;\nvoid main() {\n"
                              "    float x[RATFIT_DIM]; x[0] = 1.0;\n"
                              "    float r[RATFIT_NCHANNELS]; ratfit_eval(x, r);\n"
                              "    color = vec4(r[0]);\n}\n")
            res = subprocess.run(["glslangValidator", str(shader)], capture_output=True,
                                 text=True)
            assert res.returncode == 0, res.stdout + res.stderr
    assert not (tmp_path / "PWNED").exists()
