"""One option spec: the fitter's signature, its validation, the CLI and the batch manifest agree."""

from __future__ import annotations

import inspect

import click
import numpy as np
import pytest

from ratfit import RationalFitter, Segments
from ratfit.batch.runner import DEFAULTS, FIT_PARAMS, load_manifest, settings_id
from ratfit.cli import main
from ratfit.core.bases import FAMILIES
from ratfit.core.options import FIT_OPTIONS, SEGMENT_OPTIONS, check_fit_params
from ratfit.errors import InputError


def _command(path: str) -> click.Command:
    cmd: click.Command = main
    for part in path.split():
        cmd = cmd.get_command(click.Context(cmd), part)  # type: ignore[attr-defined]
    return cmd


def _flags(cmd: click.Command) -> dict[str, click.Parameter]:
    return {p.name: p for p in cmd.params if p.name}


def test_spec_is_the_fitters_signature() -> None:
    # the segment widths (fit(X, y)) and then the search's options
    spec = {**SEGMENT_OPTIONS, **FIT_OPTIONS}
    sig = inspect.signature(RationalFitter.__init__).parameters
    params = [k for k in sig if k != "self"]
    assert params == list(spec)
    for k, opt in spec.items():
        assert sig[k].default == opt.default, k
    assert RationalFitter().get_params() == {k: o.default for k, o in spec.items()}


@pytest.mark.parametrize("path", ["fit", "cdf", "brdf fit", "tolerance"])
def test_basis_choices_come_from_the_registry(path: str) -> None:
    basis = _flags(_command(path))["basis"]
    assert isinstance(basis.type, click.Choice)
    assert tuple(basis.type.choices) == tuple(FAMILIES)


def test_fit_command_exposes_every_cli_option_with_the_spec_default() -> None:
    flags = _flags(_command("fit"))
    for k, opt in FIT_OPTIONS.items():
        if not opt.cli:
            assert k not in flags
            continue
        assert k in flags, k
        assert flags[k].opts == [opt.flag]
        if opt.kind != "domain":
            assert flags[k].default == opt.default, k
    # Solvers are a registry (other tests register more): the built-in ones are listed.
    assert all(name in flags["solver"].help for name in ("quadprog", "daqp", "clarabel"))
    assert flags["solver"].type.name == "text"  # any registered name; the library checks it


def test_exit_codes_are_in_fit_help() -> None:
    text = _command("fit").help or ""
    assert "Exit codes: 0" in text and "1 the search found no" in text and "2 bad input" in text


@pytest.mark.parametrize(("params", "message"), [
    (dict(basis="nope"), "unknown basis 'nope'; choose one of legendre, chebyshev, monomial"),
    (dict(formulation="fast"), "unknown formulation 'fast'"),
    (dict(split_rule="max"), "unknown split rule 'max'"),
    (dict(n=0, m=2), "n must be an integer >= 1"),
    (dict(n=2.0, m=2), "n must be an integer >= 1"),
    (dict(jobs=True), "jobs must be an integer >= 1"),
    (dict(n=3), "give both n and m"),
    (dict(n=3, m=2, total=5), "exclusive"),
    (dict(min_total=8, max_total=4), "max_total must be an integer >= min_total=8"),
    (dict(domain=[[1.0, 0.0]]), "domain must be"),
    (dict(domain=[[0.0, np.nan]]), "domain must be"),
    (dict(active_set="yes"), "active_set must be true, false or absent"),
    (dict(degree=3), "unknown parameter 'degree'"),
])
def test_one_rule_one_message(params: dict, message: str) -> None:
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        check_fit_params(params)
    if "degree" in params:
        return
    x = np.linspace(0, 1, 20)
    seg = Segments.from_relative(x, 1 + x, 0.1)
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        RationalFitter(**params).fit(seg)


def test_manifest_accepts_every_fit_option_formulation_included(tmp_path) -> None:
    (tmp_path / "a.csv").write_text("x,y\n0,1\n1,2\n2,3\n")
    assert set(FIT_PARAMS) == set(FIT_OPTIONS) - {"callback"}
    assert set(FIT_PARAMS) <= set(DEFAULTS)
    entries, _, _ = load_manifest(
        {"inputs": ["a.csv"], "defaults": {"formulation": "basis", "dt": 0.1},
         "settings": [{"formulation": "arnoldi"}, {}]}, base_dir=tmp_path)
    forms = [c["formulation"] for c in entries[0].combos]
    assert forms == ["arnoldi", "basis"]
    with pytest.raises(InputError, match=r"defaults: unknown formulation 'fast'"):
        load_manifest({"inputs": ["a.csv"], "defaults": {"formulation": "fast"}},
                      base_dir=tmp_path)
    with pytest.raises(InputError, match="unknown key 'degree'"):
        load_manifest({"inputs": ["a.csv"], "defaults": {"degree": 3}}, base_dir=tmp_path)


def test_settings_id_ignores_a_new_key_at_its_default() -> None:
    base = dict(DEFAULTS)
    assert settings_id(base) == settings_id({**base, "formulation": "auto"})
    assert settings_id(base) != settings_id({**base, "formulation": "basis"})
    assert settings_id(base) == settings_id({**base, "jobs": 7})
    assert settings_id(base) == settings_id({**base, "warm_start": False})


# ------------------------------------------------------------------ checked options objects
def _brdf_seg() -> Segments:
    x = np.linspace(0.0, 1.0, 30)
    return Segments.from_relative(x, 1.0 + x, 0.1)


@pytest.mark.parametrize(("params", "message"), [
    (dict(polish="no"), "polish must be true or false, got .no."),
    (dict(physical=1), "physical must be true or false"),
    (dict(positive_q="yes"), "positive_q must be true or false"),
    (dict(parametrization="NO_SUCH"), "unknown parametrization 'NO_SUCH'"),
    (dict(used_coords=[0, 0]), "used_coords must be distinct"),
    (dict(basis="nope"), "unknown basis 'nope'"),
])
def test_brdf_fitter_options_are_checked_like_the_base_ones(params: dict, message: str) -> None:
    from ratfit.brdf import BRDFFitter

    with pytest.raises(InputError, match=message):
        BRDFFitter(**params).fit(_brdf_seg())


@pytest.mark.parametrize(("params", "message"), [
    (dict(form="three-row"), "unknown monotone form 'three-row'"),
    (dict(grid=-1), "grid must be an integer >= 0"),
    (dict(grid=True), "grid must be an integer >= 0"),
    (dict(check_points=1), "check_points must be an integer >= 2"),
    (dict(formulation="arnoldi"), "has no derivative rows"),
    (dict(solver="nope"), "unknown solver 'nope'"),
])
def test_monotone_fitter_options_are_checked_like_the_base_ones(params: dict,
                                                                message: str) -> None:
    from ratfit.cdf import MonotoneFitter

    x = np.linspace(0.0, 1.0, 30)
    with pytest.raises(InputError, match=message):
        MonotoneFitter(**params).fit(Segments.from_absolute(x, x, 0.01))


def test_each_estimator_spec_extends_the_base_spec() -> None:
    from ratfit.brdf.fitter import BRDFFitter
    from ratfit.brdf.options import BRDF_OPTIONS, BRDF_SOLVER, BRDFOptions
    from ratfit.cdf.monotone import MONOTONE_OPTIONS, MonotoneFitter, MonotoneOptions
    from ratfit.core.options import FitOptions

    for spec, cls, est in ((BRDF_OPTIONS, BRDFOptions, BRDFFitter),
                           (MONOTONE_OPTIONS, MonotoneOptions, MonotoneFitter)):
        assert list(spec)[: len(FIT_OPTIONS)] == list(FIT_OPTIONS)
        assert issubclass(cls, FitOptions) and cls.SPEC is spec
        assert est.options_type is cls
        # every constructor parameter is a checked option (or a segment width), with
        # the same default
        assert est().get_params() == {k: o.default for k, o in {**SEGMENT_OPTIONS,
                                                                  **spec}.items()}
    assert BRDF_OPTIONS["solver"].default == BRDF_SOLVER == BRDFOptions().solver
    assert MonotoneOptions().formulation == "basis"
    # names are normalised once, at the seam
    assert BRDFOptions(parametrization="rusin_th_td_pd").parametrization == "RUSIN_TH_TD_PD"
    assert FitOptions(domain=[[0, 1]]).domain == ((0.0, 1.0),)


def test_options_objects_are_checked_whenever_made() -> None:
    from dataclasses import replace

    from ratfit.core.options import FitOptions

    opts = FitOptions(time_limit=3)
    assert opts.time_limit == 3.0 and isinstance(opts.time_limit, float)
    with pytest.raises(InputError, match="give both n and m"):
        replace(opts, n=4)
    with pytest.raises(InputError, match="entry 3: unknown strategy 'fast'"):
        FitOptions.from_params({"strategy": "fast"}, where="entry 3")
    with pytest.raises(InputError, match="entry 3: n/m and total are exclusive"):
        FitOptions.from_params({"n": 2, "m": 2, "total": 4}, where="entry 3")
    assert opts.changed() == {"time_limit": 3.0}


def test_the_engine_takes_options_and_parts_not_the_fitter() -> None:
    """The search engine's signature: checked options, the parts, the data; and a
    fitter extends the search through the one public hook ``search_parts``."""
    from ratfit.fitting.search import SearchEngine

    sig = list(inspect.signature(SearchEngine.__init__).parameters)
    assert sig[:6] == ["self", "options", "parts", "space", "seg", "j"]
    for cls_path in ("ratfit.brdf.fitter.BRDFFitter", "ratfit.cdf.monotone.MonotoneFitter"):
        mod, _, name = cls_path.rpartition(".")
        cls = getattr(__import__(mod, fromlist=[name]), name)
        assert "search_parts" in vars(cls)
        assert not {"_search_parts", "_resolved_active_set"} & set(vars(cls))
