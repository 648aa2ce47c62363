"""Generator of hostile command lines: damaged copies of real data files, hand-edited fit
files, extreme numbers, wrong types and usage errors, over every subcommand.

Each case is a function of a :class:`Ctx` (a temporary folder, the shared data, and
good fit files made once per session) that writes its damaged inputs into the
temporary folder and returns the command line plus the output paths that must NOT
exist afterwards. Real data files are read from ``../shared/data`` and damaged in
the temporary folder; nothing is copied into the repository.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from conftest import write_file

Build = Callable[["Ctx"], tuple[list[Any], list[Path]]]


@dataclass(frozen=True)
class Case:
    id: str
    build: Build
    # regex that the one error line must match (case-insensitive)
    expect: str = ""


@dataclass
class Ctx:
    tmp: Path
    data: Path  # the shared data folder
    fit1d: Path  # a verified 1-D fit of a small function (ratfit fit)
    cdf: Path  # a verified CDF fit (ratfit cdf)
    csv1d: Path  # good 1-D data for that fit
    brdf: Path | None = None  # a verified 3-D BRDF fit (ratfit brdf fit, synthetic data)
    brdf_data: Path | None = None  # its data (ALTA text)

    def write(self, name: str, content: str | bytes) -> Path:
        return write_file(self.tmp, name, content)

    @property
    def out(self) -> Path:
        """A path in a folder that does not exist yet: nothing may be created there."""
        return self.tmp / "fresh" / "out"


# --------------------------------------------------------------------------- text damage
_NUM = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _numeric_lines(text: str) -> list[int]:
    lines = text.split("\n")
    return [i for i, ln in enumerate(lines)
            if ln.strip() and not ln.lstrip().startswith("#")
            and all(_NUM.match(t) for t in ln.replace(",", " ").split())]


def _edit_line(text: str, which: int, fn: Callable[[list[str]], list[str]]) -> str:
    lines = text.split("\n")
    nums = _numeric_lines(text)
    i = nums[which]
    toks = lines[i].split()
    lines[i] = " ".join(fn(toks)) + ("\r" if lines[i].endswith("\r") else "")
    return "\n".join(lines)


def _set_tok(j: int, value: str) -> Callable[[list[str]], list[str]]:
    def fn(toks: list[str]) -> list[str]:
        toks = list(toks)
        toks[j] = value
        return toks
    return fn


TEXT_DAMAGES: dict[str, Callable[[str], str | bytes]] = {
    "nan-y": lambda t: _edit_line(t, -3, _set_tok(-1, "nan")),
    "inf-y": lambda t: _edit_line(t, -3, _set_tok(-1, "inf")),
    "neg-inf-x": lambda t: _edit_line(t, 2, _set_tok(0, "-inf")),
    "word": lambda t: _edit_line(t, 1, _set_tok(-1, "abc")),
    "drop-token": lambda t: _edit_line(t, 1, lambda k: k[:-1]),
    "extra-token": lambda t: _edit_line(t, -2, lambda k: [*k, "1.0", "2.0"]),
    "y-1e308": lambda t: _edit_line(t, 0, _set_tok(-1, "1e308")),
    "x-1e305": lambda t: _edit_line(t, -1, _set_tok(0, "1e305")),
    "nul-bytes": lambda t: (t[: len(t) // 2].encode() + b"\x00\xff\xfe\x00"
                           + t[len(t) // 2:].encode()),
    "empty": lambda t: "",
    "header-only": lambda t: "\n".join(ln for i, ln in enumerate(t.split("\n"))
                                       if i not in set(_numeric_lines(t))),
    "utf16": lambda t: t.encode("utf-16"),
}

# 1-D text files (x, y) among the real data
TEXT_FILES_1D = ("alta/Kirby2.dat", "nist/MGH09.dat", "nist/ENSO.dat", "nist/Rat43.dat")


def _damaged(src: str, damage: str) -> Callable[[Ctx], Path]:
    def make(c: Ctx) -> Path:
        text = (c.data / src).read_bytes().decode("latin-1")
        out = TEXT_DAMAGES[damage](text)
        return c.write(f"damaged{Path(src).suffix}", out)
    return make


def data_cases() -> list[Case]:
    cases = []
    for src in TEXT_FILES_1D:
        stem = Path(src).stem
        for dmg in TEXT_DAMAGES:
            mk = _damaged(src, dmg)

            def fit(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
                return ["fit", mk(c), "--dt", "0.05", "-o", c.out], [c.out]

            def tol(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
                return ["tolerance", mk(c), "--n", "2", "--m", "2"], []

            def ev(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
                return ["eval", c.fit1d, mk(c), "-o", c.out], [c.out]

            def cdf(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
                return ["cdf", mk(c), "--from", "pdf", "-o", c.out], [c.out]

            def plot(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
                out = c.tmp / "fresh" / "p.png"
                return ["plot", c.fit1d, "--data", mk(c), "-o", out], [out]

            def report(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
                return ["report", c.fit1d, "--data", mk(c), "-o", c.tmp / "fresh"], \
                    [c.tmp / "fresh"]

            for cmd, fn in (("fit", fit), ("tolerance", tol), ("eval", ev), ("cdf", cdf),
                            ("plot", plot), ("report", report)):
                # every command on the small files; the big ones on fit only
                cases.append(Case(f"data-{cmd}-{stem}-{dmg}", fn))
    return cases


# --------------------------------------------------------------------------- binary damage
BINARY_FILES = ("cornell/cayman.brdf", "alta/data-example-01.exr",
                "alta/brdf_small_simu_two_layers_binary.alta",
                "alta/brdf_small_simu_two_layers_txt.alta")

BINARY_DAMAGES: dict[str, Callable[[bytes], bytes]] = {
    "half": lambda b: b[: len(b) // 2],
    "head-only": lambda b: b[:40],
    "zeroed-head": lambda b: b"\x00" * 64 + b[64:],
    "empty": lambda b: b"",
    "flipped-head": lambda b: bytes(v ^ 0x5A for v in b[:256]) + b[256:],
}


def binary_cases() -> list[Case]:
    cases = []
    for src in BINARY_FILES:
        name = Path(src).name
        for dmg, fn in BINARY_DAMAGES.items():
            def fit(c: Ctx, src=src, fn=fn, name=name) -> tuple[list[Any], list[Path]]:
                p = c.write(name, fn((c.data / src).read_bytes()))
                return ["brdf", "fit", p, "--dt", "0.1", "-o", c.out], [c.out]

            cases.append(Case(f"brdf-fit-{name}-{dmg}", fit))
    return cases


# --------------------------------------------------------------------------- fit files
def _set(path: list[Any], value: Any) -> Callable[[dict], dict]:
    def fn(doc: dict) -> dict:
        d: Any = doc
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value
        return doc
    return fn


def _delete(path: list[Any]) -> Callable[[dict], dict]:
    def fn(doc: dict) -> dict:
        d: Any = doc
        for k in path[:-1]:
            d = d[k]
        del d[path[-1]]
        return doc
    return fn


def _scale(key: str, factor: float) -> Callable[[dict], dict]:
    def fn(doc: dict) -> dict:
        ch = doc["channels"][0]
        ch[key] = [v * factor for v in ch[key]]
        return doc
    return fn


def _pole_in(doc: dict) -> dict:
    # q -> the second basis function, which changes sign inside the domain: a pole
    ch = doc["channels"][0]
    ch["q"] = [0.0, 1.0] + [0.0] * max(0, len(ch["q"]) - 2)
    return doc


def _deep(depth: int) -> str:
    return '{"format": "ratfit.fit", "version": 3, "space": ' + "[" * depth + "]" * depth + "}"


FIT_EDITS: dict[str, Callable[[dict], dict] | str | bytes] = {
    # wrong JSON types of each field
    "name-int": _set(["channels", 0, "name"], 123),
    "name-null": _set(["channels", 0, "name"], None),
    "name-list": _set(["channels", 0, "name"], ["a"]),
    "name-object": _set(["channels", 0, "name"], {"a": 1}),
    "p_basis-string": _set(["channels", 0, "p_basis"], "arnoldi"),
    "p_basis-list": _set(["channels", 0, "p_basis"], [1, 2]),
    "p_basis-number": _set(["channels", 0, "p_basis"], 5),
    "p_basis-H-strings": lambda d: _set(["channels", 0, "p_basis"], {
        "kind": "arnoldi", "size": 1, "parents": [0], "dims": [0], "H_upper": ["x"]})(d),
    "diagnostics-string": _set(["channels", 0, "diagnostics"], "verified"),
    "diagnostics-list": _set(["channels", 0, "diagnostics"], [True]),
    "diagnostics-number": _set(["channels", 0, "diagnostics"], 1),
    "provenance-string": _set(["provenance"], "me"),
    "provenance-list": _set(["provenance"], ["me"]),
    "provenance-number": _set(["provenance"], 7),
    "monomial-string": _set(["channels", 0, "monomial"], "x^2"),
    "space-string": _set(["space"], "legendre"),
    "space-list": _set(["space"], []),
    "family-number": _set(["space", "family"], 3),
    "family-unknown": _set(["space", "family"], "hermite"),
    "index-set-unknown": _set(["space", "index_set"], "sparse"),
    "domain-string": _set(["space", "domain"], "0..1"),
    "domain-flat": _set(["space", "domain"], [0, 1]),
    "domain-reversed": _set(["space", "domain"], [[1.0, 0.0]]),
    "domain-huge": _set(["space", "domain"], [[-1e308, 1e308]]),
    "domain-subnormal": _set(["space", "domain"], [[0.0, 1e-320]]),
    "domain-strings": _set(["space", "domain"], [["0", "1"]]),
    "channels-object": _set(["channels"], {"0": 1}),
    "channels-empty": _set(["channels"], []),
    "channels-numbers": _set(["channels"], [1, 2]),
    "p-string": _set(["channels", 0, "p"], "1 2 3"),
    "p-empty": _set(["channels", 0, "p"], []),
    "p-strings": _set(["channels", 0, "p"], ["1", "2"]),
    "p-bools": _set(["channels", 0, "p"], [True, False]),
    "p-nested": _set(["channels", 0, "p"], [[1.0], [2.0]]),
    "q-zero": lambda d: _set(["channels", 0, "q"], [0.0] * len(d["channels"][0]["q"]))(d),
    "p-1e308": _scale("p", 1e308),
    "q-1e308": lambda d: _set(["channels", 0, "q"], [1e308] * len(d["channels"][0]["q"]))(d),
    "huge-int-coefficient": "HUGEINT",
    "version-string": _set(["version"], "3"),
    "version-bool": _set(["version"], True),
    "version-zero": _set(["version"], 0),
    "version-future": _set(["version"], 99),
    "format-wrong": _set(["format"], "alta.fit"),
    "no-space": _delete(["space"]),
    "no-channels": _delete(["channels"]),
    "no-q": _delete(["channels", 0, "q"]),
    "n-mismatch": _set(["channels", 0, "n"], 99),
    "indices-wrong": _set(["channels", 0, "p_indices"], [[7]]),
    "deep-nesting": "DEEP",
    "truncated": "TRUNC",
    "binary": b"\x89PNG\r\n\x1a\n" + bytes(range(256)),
    "top-list": "[1, 2, 3]",
    "nan-token": "NANTOKEN",
    # tampering: valid files whose content no longer matches the digest
    "tamper-numerator-scaled": _scale("p", 1.5),
    "tamper-pole-moved-in": _pole_in,
    "tamper-recurrence-deleted": _delete(["channels", 0, "p_basis"]),
    "tamper-digest-deleted": _delete(["digest"]),
    "tamper-digest-garbage": _set(["digest"], "sha256:" + "0" * 64),
    "tamper-digest-number": _set(["digest"], 5),
    "tamper-verified-flag": _set(["channels", 0, "diagnostics", "max_violation"], -1.0),
    "tamper-domain-shifted": lambda d: _set(["space", "domain"],
                                            [[v + 0.5 for v in d["space"]["domain"][0]]])(d),
}


def _edited_fit(src_attr: str, edit: Callable[[dict], dict] | str | bytes,
                name: str = "edited.json") -> Callable[[Ctx], Path]:
    def make(c: Ctx) -> Path:
        text = getattr(c, src_attr).read_text()
        if isinstance(edit, bytes):
            return c.write(name, edit)
        if edit == "DEEP":
            return c.write(name, _deep(200_000))
        if edit == "TRUNC":
            return c.write(name, text[: len(text) // 3])
        if edit == "HUGEINT":
            doc = json.loads(text)
            doc["channels"][0]["p"][0] = 12345
            return c.write(name, json.dumps(doc).replace("12345", "9" * 5000, 1))
        if edit == "NANTOKEN":
            doc = json.loads(text)
            doc["channels"][0]["p"][0] = 12345.5
            return c.write(name, json.dumps(doc).replace("12345.5", "NaN", 1))
        if isinstance(edit, str):
            return c.write(name, edit)
        return c.write(name, json.dumps(edit(json.loads(text))))
    return make


def fit_file_cases() -> list[Case]:
    cases = []
    for key, edit in FIT_EDITS.items():
        mk = _edited_fit("fit1d", edit)
        expect = "digest|edited" if key.startswith("tamper") else ""

        def ev(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["eval", mk(c), c.csv1d, "-o", c.out], [c.out]

        def exp_c(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["export", mk(c), "--lang", "c", "-o", c.out], [c.out]

        def exp_py(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["export", mk(c), "--lang", "python", "-o", c.out], [c.out]

        def plot(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            out = c.tmp / "fresh" / "p.png"
            return ["plot", mk(c), "-o", out], [out]

        def report(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["report", mk(c), "-o", c.tmp / "fresh"], [c.tmp / "fresh"]

        for cmd, fn in (("eval", ev), ("export-c", exp_c), ("export-py", exp_py),
                        ("plot", plot), ("report", report)):
            cases.append(Case(f"fitfile-{cmd}-{key}", fn, expect))
    # the CDF sampler reads the same format
    for key in ("name-int", "diagnostics-string", "provenance-list", "q-zero", "p-1e308",
                "domain-huge", "domain-subnormal", "deep-nesting", "huge-int-coefficient",
                "tamper-numerator-scaled", "tamper-pole-moved-in", "tamper-digest-deleted",
                "truncated", "version-future"):
        mk = _edited_fit("cdf", FIT_EDITS[key])

        def smp(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            out = c.tmp / "fresh" / "s.npy"
            return ["sample", mk(c), "-n", "10", "-o", out], [out]

        cases.append(Case(f"fitfile-sample-{key}", smp,
                          "digest|edited" if key.startswith("tamper") else ""))
    # brdf eval / compare with a non-BRDF or damaged fit
    for key in ("name-int", "p_basis-string", "tamper-numerator-scaled", "truncated"):
        mk = _edited_fit("fit1d", FIT_EDITS[key])

        def bcmp(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["brdf", "compare", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta",
                    mk(c)], []

        cases.append(Case(f"fitfile-brdf-compare-{key}", bcmp))
    return cases


# --------------------------------------------------------------------------- options
def _fit_opts(*opts: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        return ["fit", c.csv1d, *opts, "-o", c.out], [c.out]
    return b


def _cdf_opts(*opts: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        return ["cdf", c.csv1d, *opts, "-o", c.out], [c.out]
    return b


def _tol_opts(*opts: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        return ["tolerance", c.csv1d, *opts], []
    return b


def _sample_opts(*opts: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        out = c.tmp / "fresh" / "s.npy"
        return ["sample", c.cdf, *opts, "-o", out], [out]
    return b


def _plot_opts(*opts: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        out = c.tmp / "fresh" / "p.png"
        return ["plot", c.fit1d, *opts, "-o", out], [out]
    return b


def _export_opts(*opts: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        return ["export", c.fit1d, *opts, "-o", c.out], [c.out]
    return b


EXTREME = ("nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "1e-320")
BIG_INTS = ("0", "-1", "1000000000", "99999999999999999999")

OPTION_CASES: dict[str, Build] = {}
for v in EXTREME:
    OPTION_CASES[f"fit-dt-{v}"] = _fit_opts("--dt", v)
    OPTION_CASES[f"fit-abs-width-{v}"] = _fit_opts("--abs-width", v)
    OPTION_CASES[f"fit-domain-{v}"] = _fit_opts("--dt", "0.1", "--domain", v, "1")
    OPTION_CASES[f"cdf-abs-width-{v}"] = _cdf_opts("--abs-width", v)
    OPTION_CASES[f"cdf-dt-{v}"] = _cdf_opts("--dt", v)
    if v != "1e-320":  # a (silly) valid tolerance
        OPTION_CASES[f"tolerance-rtol-{v}"] = _tol_opts("--n", "2", "--m", "2", "--rtol", v)
for v in ("1e308", "nan", "-inf"):
    OPTION_CASES[f"cdf-domain-{v}"] = _cdf_opts("--domain", "0", v)
    OPTION_CASES[f"fit-domain-hi-{v}"] = _fit_opts("--dt", "0.1", "--domain", "0", v)
for v in BIG_INTS:
    OPTION_CASES[f"fit-min-total-{v}"] = _fit_opts("--dt", "0.1", "--min-total", v)
    OPTION_CASES[f"fit-total-{v}"] = _fit_opts("--dt", "0.1", "--total", v)
    OPTION_CASES[f"fit-n-m-{v}"] = _fit_opts("--dt", "0.1", "--n", v, "--m", "2")
    OPTION_CASES[f"fit-channel-{v}"] = _fit_opts("--dt", "0.1", "--channel", v if v != "0"
                                                 else "1")
    OPTION_CASES[f"fit-jobs-{v}"] = _fit_opts("--dt", "0.1", "--jobs", v) if v in (
        "0", "-1", "99999999999999999999") else _fit_opts("--dt", "0.1", "--jobs", "x")
    OPTION_CASES[f"tolerance-n-{v}"] = _tol_opts("--n", v, "--m", "2") if v != "1000000000" \
        else _tol_opts("--n", "2", "--m", "2", "--channel", v)
    OPTION_CASES[f"sample-n-{v}"] = _sample_opts("-n", v) if v in ("0", "-1") else \
        _sample_opts("-n", "10", "--seed", "-" + v)
    OPTION_CASES[f"plot-channel-{v}"] = _plot_opts("--channel", v if v != "0" else "7")
    OPTION_CASES[f"plot-dim-{v}"] = _plot_opts("--dim", v if v != "0" else "3")
    OPTION_CASES[f"cdf-points-{v}"] = _cdf_opts("--from", "samples", "--points", v) \
        if v in ("0", "-1") else _cdf_opts("--channel", v)
OPTION_CASES.update({
    "fit-max-below-min": _fit_opts("--dt", "0.1", "--min-total", "10", "--max-total", "4"),
    "fit-basis-bogus": _fit_opts("--dt", "0.1", "--basis", "hermite"),
    "fit-solver-bogus": _fit_opts("--dt", "0.1", "--solver", "nope"),
    "fit-format-wrong": _fit_opts("--dt", "0.1", "--format", "nist"),
    "fit-format-npz": _fit_opts("--dt", "0.1", "--format", "npz"),
    "fit-no-width": _fit_opts(),
    "fit-dt-word": _fit_opts("--dt", "ten"),
    "fit-domain-one-number": _fit_opts("--dt", "0.1", "--domain", "0"),
    "fit-two-domains-1d": _fit_opts("--dt", "0.1", "--domain", "0", "1", "--domain", "0", "1"),
    "fit-shared-and-n": _fit_opts("--dt", "0.1", "--shared-denominator", "--n", "3"),
    "cdf-confidence-0": _cdf_opts("--from", "samples", "--confidence", "0"),
    "cdf-confidence-1": _cdf_opts("--from", "samples", "--confidence", "1"),
    "cdf-confidence-nan": _cdf_opts("--from", "samples", "--confidence", "nan"),
    "cdf-grid-neg": _cdf_opts("--grid", "-1"),
    "cdf-form-bogus": _cdf_opts("--form", "three-row"),
    "cdf-domain-reversed": _cdf_opts("--domain", "1", "0"),
    "tolerance-rtol-2": _tol_opts("--n", "2", "--m", "2", "--rtol", "2"),
    "tolerance-no-n": _tol_opts("--m", "2"),
    "sample-n-word": _sample_opts("-n", "many"),
    "sample-seed-float": _sample_opts("-n", "3", "--seed", "1.5"),
    "sample-not-cdf": lambda c: (["sample", c.fit1d, "-n", "3", "-o", c.tmp / "fresh" / "s.npy"],
                                 [c.tmp / "fresh" / "s.npy"]),
    "plot-jpg": lambda c: (["plot", c.fit1d, "-o", c.tmp / "fresh" / "p.jpg"],
                           [c.tmp / "fresh" / "p.jpg"]),
    "plot-kind-error-no-data": _plot_opts("--kind", "error"),
    "plot-kind-polar-not-brdf": _plot_opts("--kind", "polar"),
    "plot-kind-sphere-not-brdf": _plot_opts("--kind", "sphere"),
    "plot-size-0": _plot_opts("--size", "0"),
    "plot-size-neg": _plot_opts("--size", "-5"),
    "plot-model-bogus": _plot_opts("--model", "lambert+unicorn"),
    "plot-data-missing": _plot_opts("--data", "/nonexistent/d.csv"),
    "export-lang-bogus": _export_opts("--lang", "rust"),
    "export-no-lang": _export_opts(),
    "export-form-bogus": _export_opts("--lang", "c", "--form", "fast"),
    "export-prefix-space": _export_opts("--lang", "c", "--prefix", "my fit"),
    "export-prefix-digit": _export_opts("--lang", "python", "--prefix", "1fit"),
    "export-prefix-empty": _export_opts("--lang", "glsl", "--prefix", ""),
    "report-no-outdir": lambda c: (["report", c.fit1d], []),
    "report-outdir-is-file": lambda c: (["report", c.fit1d, "-o", c.fit1d], []),
    "eval-no-input": lambda c: (["eval", c.fit1d], []),
    "eval-dim-mismatch": lambda c: (["eval", c.fit1d, c.write("d2.csv", "a,b,y\n0,1,2\n1,2,3\n"),
                                     "-o", c.out], [c.out]),
    "eval-output-dir": lambda c: (["eval", c.fit1d, c.csv1d, "-o", c.tmp], []),
    "eval-data-is-fit": lambda c: (["eval", c.fit1d, c.fit1d, "-o", c.out], [c.out]),
    "fit-input-is-dir": lambda c: (["fit", c.tmp, "--dt", "0.1", "-o", c.out], [c.out]),
    "fit-input-missing": lambda c: (["fit", c.tmp / "nope.csv", "--dt", "0.1", "-o", c.out],
                                    [c.out]),
    "fit-output-in-missing-readonly": lambda c: (
        ["fit", c.csv1d, "--dt", "0.1", "-o", "/proc/nope/fit.json"], []),
    "demo-addendum-solver": lambda c: (["demo", "addendum", "--solver", "nope", "-o",
                                        c.tmp / "fresh"], [c.tmp / "fresh"]),
    "demo-unknown": lambda c: (["demo", "bogus"], []),
    "brdf-fit-param-bogus": lambda c: (
        ["brdf", "fit", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta", "--param",
         "NOT_A_PARAM", "--dt", "0.1", "-o", c.out], [c.out]),
    "brdf-fit-channel-bogus": lambda c: (
        ["brdf", "fit", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta", "--channels",
         "purple", "--dt", "0.1", "-o", c.out], [c.out]),
    "brdf-fit-1d-data": lambda c: (["brdf", "fit", c.csv1d, "--dt", "0.1", "-o", c.out],
                                   [c.out]),
    "brdf-fit-dt-nan": lambda c: (
        ["brdf", "fit", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta", "--dt", "nan",
         "-o", c.out], [c.out]),
    "brdf-fit-max-points-0": lambda c: (
        ["brdf", "fit", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta", "--dt", "0.1",
         "--max-points", "0", "-o", c.out], [c.out]),
    "brdf-eval-not-brdf": lambda c: (["brdf", "eval", c.fit1d], []),
    "brdf-compare-no-fits": lambda c: (["brdf", "compare", c.csv1d], []),
    "brdf-compare-model-bogus": lambda c: (
        ["brdf", "compare", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta", "--model",
         "unicorn"], []),
})


# --------------------------------------------------------------------------- batch
def _manifest(text: str, name: str = "m.toml", **kw: Any) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        body = text.replace("@CSV@", str(c.csv1d)).replace("@TMP@", str(c.tmp))
        m = c.write(name, body)
        return ["batch", m, "-o", c.tmp / "fresh", *kw.get("opts", ())], [c.tmp / "fresh"]
    return b


BATCH_CASES: dict[str, Build] = {
    "not-toml": _manifest("inputs = [[[\n"),
    "empty": _manifest(""),
    "inputs-number": _manifest("inputs = 5\n"),
    "inputs-strings": _manifest('inputs = ["@CSV@"]\n'),
    "input-missing-file": _manifest('[[inputs]]\npath = "@TMP@/none.csv"\n'),
    "input-no-path": _manifest('[[inputs]]\nchannels = [0]\n'),
    "unknown-top-key": _manifest('colour = 1\n[[inputs]]\npath = "@CSV@"\n'),
    "unknown-setting": _manifest('[defaults]\nspeed = 11\n[[inputs]]\npath = "@CSV@"\n'),
    "dt-string": _manifest('[defaults]\ndt = "ten"\n[[inputs]]\npath = "@CSV@"\n'),
    "dt-negative": _manifest('[defaults]\ndt = -1.0\n[[inputs]]\npath = "@CSV@"\n'),
    "basis-bogus": _manifest('[defaults]\nbasis = "hermite"\n[[inputs]]\npath = "@CSV@"\n'),
    "max-total-bool": _manifest('[defaults]\nmax_total = true\n[[inputs]]\npath = "@CSV@"\n'),
    "channels-string": _manifest('[[inputs]]\npath = "@CSV@"\nchannels = "all"\n'),
    "json-list": _manifest("[1, 2]", "m.json"),
    "json-broken": _manifest('{"inputs": [', "m.json"),
    "json-deep": lambda c: _manifest("[" * 100_000 + "]" * 100_000, "m.json")(c),
    "unknown-suffix": _manifest("inputs = []", "m.yaml"),
    "scheduler-not-url": _manifest('[[inputs]]\npath = "@CSV@"\n[defaults]\ndt = 0.1\n',
                                   opts=("--scheduler", "not a url")),
    "scheduler-and-workers": _manifest('[[inputs]]\npath = "@CSV@"\n',
                                       opts=("--scheduler", "tcp://127.0.0.1:1",
                                             "--workers", "2")),
    "workers-0": _manifest('[[inputs]]\npath = "@CSV@"\n', opts=("--workers", "0")),
}


def _npz_members(members: dict[str, bytes]) -> Build:
    def b(c: Ctx) -> tuple[list[Any], list[Path]]:
        import zipfile

        p = c.tmp / "d.npz"
        with zipfile.ZipFile(p, "w") as z:
            for name, body in members.items():
                z.writestr(name, body)
        return ["fit", p, "--dt", "0.1", "-o", c.out], [c.out]
    return b


NPZ_CASES: dict[str, Build] = {
    "members-not-npy": _npz_members({"x.npy": b"hello", "y.npy": b"abc"}),
    "members-text": _npz_members({"x.txt": b"1 2 3", "y.txt": b"4 5 6"}),
    "member-truncated-npy": _npz_members({"x.npy": b"\x93NUMPY\x01\x00v\x00{'descr'",
                                          "y.npy": b""}),
    "empty-zip": _npz_members({}),
}


# --------------------------------------------------------------------------- usage
COMMANDS = (
    ["fit"], ["eval"], ["cdf"], ["sample"], ["tolerance"], ["batch"], ["export"], ["plot"],
    ["report"], ["brdf", "fit"], ["brdf", "eval"], ["brdf", "compare"], ["demo", "addendum"],
    ["demo", "cdf"],
)


def usage_cases() -> list[Case]:
    cases = []
    for cmd in COMMANDS:
        name = "-".join(cmd)

        def unknown(c: Ctx, cmd=cmd) -> tuple[list[Any], list[Path]]:
            return [*cmd, "--frobnicate"], []

        cases.append(Case(f"usage-{name}-unknown-option", unknown, "frobnicate"))
        if cmd[0] not in ("demo",):
            def missing(c: Ctx, cmd=cmd) -> tuple[list[Any], list[Path]]:
                return [*cmd], []

            cases.append(Case(f"usage-{name}-missing-argument", missing, "missing|usage"))

            def extra(c: Ctx, cmd=cmd) -> tuple[list[Any], list[Path]]:
                return [*cmd, "a", "b", "c", "d"], []

            cases.append(Case(f"usage-{name}-extra-arguments", extra, ""))
    cases.append(Case("usage-unknown-command", lambda c: (["frobnicate"], []), "frobnicate"))
    cases.append(Case("usage-brdf-unknown", lambda c: (["brdf", "frobnicate"], []),
                      "frobnicate"))
    return cases


def _comma_column(src: str) -> Callable[[Ctx], Path]:
    """One column of the file's y values written with decimal commas ("0,0082")."""
    def make(c: Ctx) -> Path:
        text = (c.data / src).read_bytes().decode("latin-1")
        lines = text.split("\n")
        ys = [lines[i].split()[-1] for i in _numeric_lines(text)]
        body = "\n".join(f"{float(v):.4f}".replace(".", ",") for v in ys) + "\n"
        return c.write("comma.csv", body)
    return make


def misparse_cases() -> list[Case]:
    cases = []
    for src in TEXT_FILES_1D:
        mk = _comma_column(src)
        for cmd, build in (
            ("fit", lambda c, mk=mk: (["fit", mk(c), "--dt", "0.1", "-o", c.out], [c.out])),
            ("cdf", lambda c, mk=mk: (["cdf", mk(c), "-o", c.out], [c.out])),
            ("tolerance", lambda c, mk=mk: (["tolerance", mk(c), "--n", "2", "--m", "2"], [])),
            ("eval", lambda c, mk=mk: (["eval", c.fit1d, mk(c), "-o", c.out], [c.out])),
        ):
            cases.append(Case(f"comma-{cmd}-{Path(src).stem}", build, "decimal comma"))
    return cases


# --------------------------------------------------------------------------- re-sealed files
# The digest is no signature: whoever edits a fit file can write the digest of the edit.
# What can be proved or checked is checked again on load, whatever the digest says.
def _reseal(edit: Callable[[dict], Any]) -> Callable[[dict], dict]:
    def fn(doc: dict) -> dict:
        from ratfit.io.fitfile import content_digest

        edit(doc)
        doc["digest"] = content_digest(doc)
        return doc
    return fn


def _legendre_q(q: list[float]) -> Callable[[dict], None]:
    """q replaced by Legendre coefficients (the Arnoldi recurrence dropped), p = 1."""
    def edit(doc: dict) -> None:
        doc["space"]["family"] = "legendre"
        ch = doc["channels"][0]
        for key in ("p_basis", "q_basis", "p_indices", "q_indices", "n", "m"):
            ch.pop(key, None)
        ch["p"], ch["q"], ch["monomial"] = [1.0], list(q), None
    return edit


def _in(path: list[Any], value: Any) -> Callable[[dict], None]:
    def edit(doc: dict) -> None:
        _set(path, value)(doc)
    return edit


def _brdf_block(block: dict) -> Callable[[dict], None]:
    def edit(doc: dict) -> None:
        doc["brdf"] = block
    return edit


_A, _B = 0.2501, 0.2509  # two roots between neighbouring points of a 1001-point scan
RESEALED_1D: dict[str, tuple[Callable[[dict], Any], str]] = {
    # 3 (t - c)^2 = 2 P2 - 6c P1 + 1 + 3c^2: a double root, exact in floats
    "double-root": (_legendre_q([1.0 + 3 * 0.0625, -6 * 0.25, 2.0]), "pole"),
    "double-root-at-end": (_legendre_q([4.0, -6.0, 2.0]), "pole"),
    "rounded-double-root": (_legendre_q([0.09 + 1 / 3, -0.6, 2 / 3]), "pole"),
    "two-close-roots": (_legendre_q([_A * _B + 1 / 3, -(_A + _B), 2 / 3]), "pole"),
    "simple-root": (_legendre_q([0.0, 1.0]), "pole"),
    "degree-above-cap": (_legendre_q([3.0] + [1e-3] * 200), "degree"),
    "verified-string": (_in(["channels", 0, "diagnostics", "verified"], "yes"), "verified"),
    "verified-number": (_in(["channels", 0, "diagnostics", "verified"], 1), "verified"),
    "diagnostics-n-string": (_in(["channels", 0, "diagnostics", "n"], "3"), "'n'"),
    "diagnostics-linf-string": (_in(["channels", 0, "diagnostics", "linf"], "0"), "linf"),
    "provenance-segments-list": (_in(["provenance", "segments"], [0.01]), "segments"),
    "provenance-dt-string": (_in(["provenance", "segments", "dt"], "0.01"), "segments"),
    "provenance-command-string": (_in(["provenance", "command"], "ratfit fit"), "command"),
    "provenance-input-number": (_in(["provenance", "input"], 5), "input"),
    "brdf-block-unknown-param": (_brdf_block({"parametrization": "NOPE"}), "NOPE"),
    "brdf-block-param-number": (_brdf_block({"parametrization": 3}), "parametrization"),
    "brdf-block-cosine-no": (_brdf_block({"parametrization": "RUSIN_TH_TD_PD",
                                          "cosine_weighted": "no"}), "cosine_weighted"),
    "brdf-block-dropped-number": (_brdf_block({"parametrization": "RUSIN_TH_TD_PD",
                                               "dropped_coords": 5}), "dropped_coords"),
}

RESEALED_BRDF: dict[str, tuple[Callable[[dict], Any], str]] = {
    f"brdf-{k}": (_in(["brdf", field], value), field) for k, field, value in (
        ("cosine-no", "cosine_weighted", "no"),
        ("cosine-string-true", "cosine_weighted", "true"),
        ("fold-null", "fold_phi_d", None),
        ("positive-q-number", "positive_q", 0),
        ("dropped-number", "dropped_coords", 5),
        ("dropped-list", "dropped_coords", [1]),
        ("dropped-string", "dropped_coords", "12"),
        ("dropped-negative", "dropped_coords", {"-1": 0.5}),
        ("dropped-out-of-range", "dropped_coords", {"9": 0.5}),
        ("dropped-value-nan", "dropped_coords", {"0": "nan"}),
        ("param-number", "parametrization", 3),
        ("param-unknown", "parametrization", "NOT_A_PARAM"),
        ("clamp-string", "clamp", "0"),
        ("segments-string", "segments", "5%"),
        ("channel-names-string", "channel_names", "R"),
        ("validity-number", "validity", 1),
        ("verified-on-number", "verified_on", 600),
        ("subset-bigger-than-data", "subset", {"points": 900, "of": 600}),
    )
}


def _resealed(src_attr: str, edit: Callable[[dict], Any], name: str) -> Callable[[Ctx], Path]:
    def make(c: Ctx) -> Path:
        src = getattr(c, src_attr)
        assert src is not None, f"no {src_attr} fit in this context"
        doc = _reseal(edit)(json.loads(src.read_text()))
        return c.write(name, json.dumps(doc))
    return make


def resealed_cases() -> list[Case]:
    cases = []
    for key, (edit, expect) in RESEALED_1D.items():
        mk = _resealed("fit1d", edit, "resealed.json")

        def ev(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["eval", mk(c), c.csv1d, "-o", c.out], [c.out]

        def exp_c(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["export", mk(c), "--lang", "c", "-o", c.out], [c.out]

        def exp_py(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["export", mk(c), "--lang", "python", "-o", c.out], [c.out]

        def plot(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            out = c.tmp / "fresh" / "p.png"
            return ["plot", mk(c), "-o", out], [out]

        def report(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["report", mk(c), "-o", c.tmp / "fresh"], [c.tmp / "fresh"]

        for cmd, fn in (("eval", ev), ("export-c", exp_c), ("export-py", exp_py),
                        ("plot", plot), ("report", report)):
            if cmd == "eval" and key == "brdf-block-unknown-param":
                continue  # eval reads points, never the parametrization: nothing to refuse
            cases.append(Case(f"resealed-{cmd}-{key}", fn, expect))
    for key, (edit, expect) in RESEALED_BRDF.items():
        mk = _resealed("brdf", edit, "resealed-brdf.json")

        def bexp(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["export", mk(c), "--lang", "glsl", "-o", c.out], [c.out]

        def beval(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["brdf", "eval", mk(c), "--data", c.brdf_data], []

        def bplot(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            out = c.tmp / "fresh" / "p.png"
            return ["plot", mk(c), "--kind", "polar", "-o", out], [out]

        def breport(c: Ctx, mk=mk) -> tuple[list[Any], list[Path]]:
            return ["report", mk(c), "-o", c.tmp / "fresh"], [c.tmp / "fresh"]

        for cmd, fn in (("export", bexp), ("brdf-eval", beval), ("plot", bplot),
                        ("report", breport)):
            cases.append(Case(f"resealed-{cmd}-{key}", fn, expect))
    return cases


# --------------------------------------------------------------------------- output targets
def _file_in(c: Ctx, name: str = "plain.txt") -> Path:
    return c.write(name, "not a folder\n")


def _dir_in(c: Ctx, name: str) -> Path:
    d = c.tmp / name
    d.mkdir(exist_ok=True)
    return d


def _link_to_dir(c: Ctx) -> Path:
    link = c.tmp / "to-dir"
    if not link.is_symlink():
        link.symlink_to(_dir_in(c, "real-dir"))
    return link


OUTPUT_CASES: dict[str, Build] = {
    "fit-output-is-dir": lambda c: (["fit", c.csv1d, "--dt", "0.1", "-o", _dir_in(c, "o")],
                                    []),
    "fit-output-link-to-dir": lambda c: (["fit", c.csv1d, "--dt", "0.1", "-o", _link_to_dir(c)],
                                         []),
    "fit-output-under-a-file": lambda c: (["fit", c.csv1d, "--dt", "0.1", "-o",
                                           _file_in(c) / "fit.json"], []),
    "cdf-output-under-a-file": lambda c: (["cdf", c.csv1d, "-o", _file_in(c) / "cdf.json"], []),
    "eval-output-link-to-dir": lambda c: (["eval", c.fit1d, c.csv1d, "-o", _link_to_dir(c)], []),
    "eval-output-under-a-file": lambda c: (["eval", c.fit1d, c.csv1d, "-o",
                                            _file_in(c) / "v.csv"], []),
    "export-output-is-dir": lambda c: (["export", c.fit1d, "--lang", "c", "-o",
                                        _dir_in(c, "code")], []),
    "export-output-under-a-file": lambda c: (["export", c.fit1d, "--lang", "c", "-o",
                                              _file_in(c) / "x.c"], []),
    "sample-output-dir-named-npy": lambda c: (["sample", c.cdf, "-n", "5", "-o",
                                               _dir_in(c, "s.npy")], []),
    "sample-output-dash": lambda c: (["sample", c.cdf, "-n", "5", "-o", "-"], []),
    "plot-output-dir-named-png": lambda c: (["plot", c.fit1d, "-o", _dir_in(c, "p.png")], []),
    "plot-output-dash": lambda c: (["plot", c.fit1d, "-o", "-"], []),
    "report-output-under-a-file": lambda c: (["report", c.fit1d, "-o", _file_in(c) / "rep"], []),
    "report-output-link-to-file": lambda c: (
        ["report", c.fit1d, "-o", _link_to(c, _file_in(c))], []),
    "report-output-dash": lambda c: (["report", c.fit1d, "-o", "-"], [c.tmp / "-"]),
    "demo-cdf-output-is-file": lambda c: (["demo", "cdf", "-o", _file_in(c)], []),
    "batch-output-under-a-file": lambda c: (
        ["batch", c.write("m.toml", f'[defaults]\ndt = 0.1\n[[inputs]]\npath = "{c.csv1d}"\n'),
         "-o", _file_in(c) / "b"], []),
}


def _link_to(c: Ctx, target: Path) -> Path:
    link = c.tmp / "link"
    if not link.is_symlink():
        link.symlink_to(target)
    return link


# --------------------------------------------------------------------------- numeric bounds
BOUND_CASES: dict[str, Build] = {
    "sample-n-2^63": _sample_opts("-n", "9223372036854775808"),
    "sample-n-1e20": _sample_opts("-n", "99999999999999999999"),
    "cdf-points-2^63": lambda c: (["cdf", c.write("s.txt", "\n".join(
        str(v / 7) for v in range(60))), "--from", "samples", "--points",
        "9223372036854775808", "-o", c.out], [c.out]),
    "cdf-grid-2^63": _cdf_opts("--grid", "9223372036854775808"),
    "cdf-grid-1e20": _cdf_opts("--grid", "99999999999999999999"),
    "batch-workers-2^63": _manifest('[defaults]\ndt = 0.1\n[[inputs]]\npath = "@CSV@"\n',
                                    opts=("--workers", "9223372036854775808")),
    "batch-allowed-failures-2^63": _manifest(
        '[defaults]\ndt = 0.1\n[[inputs]]\npath = "@CSV@"\n',
        opts=("--allowed-failures", "9223372036854775808")),
    "brdf-compare-starts-2^63": lambda c: (
        ["brdf", "compare", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta",
         "--model", "lambert", "--starts", "9223372036854775808"], []),
    "brdf-compare-starts-0": lambda c: (
        ["brdf", "compare", c.data / "alta" / "brdf_small_simu_two_layers_txt.alta",
         "--model", "lambert", "--starts", "0"], []),
    "render-seed-negative": lambda c: (["render", c.fit1d, "-o", c.tmp / "fresh" / "r.png",
                                        "--seed", "-1"], [c.tmp / "fresh"]),
    "render-seed-2^32": lambda c: (["render", c.fit1d, "-o", c.tmp / "fresh" / "r.png",
                                    "--seed", str(2**32)], [c.tmp / "fresh"]),
    "render-cosine-weight-nan": lambda c: (["render", c.fit1d, "-o", c.tmp / "fresh" / "r.png",
                                            "--cosine-weight", "nan"], [c.tmp / "fresh"]),
    "tolerance-rtol-nan-click": _tol_opts("--n", "2", "--m", "2", "--rtol", "NaN"),
}


# what the one error line must name (the option, not some later failure)
_BOUND_SAYS = {
    "sample-n-2^63": "'-n'", "sample-n-1e20": "'-n'", "cdf-points-2^63": "--points",
    "cdf-grid-2^63": "--grid", "cdf-grid-1e20": "--grid", "batch-workers-2^63": "--workers",
    "batch-allowed-failures-2^63": "--allowed-failures",
    "brdf-compare-starts-2^63": "--starts", "brdf-compare-starts-0": "starts",
    "render-seed-negative": "--seed", "render-seed-2^32": "--seed",
    "render-cosine-weight-nan": "--cosine-weight", "tolerance-rtol-nan-click": "rtol",
}


def all_cases() -> list[Case]:
    cases = data_cases() + binary_cases() + fit_file_cases() + usage_cases()
    cases += misparse_cases()
    cases += [Case(f"option-{k}", b) for k, b in OPTION_CASES.items()]
    cases += [Case(f"batch-{k}", b) for k, b in BATCH_CASES.items()]
    cases += [Case(f"npz-{k}", b) for k, b in NPZ_CASES.items()]
    cases += resealed_cases()
    cases += [Case(f"output-{k}", b) for k, b in OUTPUT_CASES.items()]
    cases += [Case(f"bound-{k}", b, _BOUND_SAYS.get(k, "")) for k, b in BOUND_CASES.items()]
    return cases
