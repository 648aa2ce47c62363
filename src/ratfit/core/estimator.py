"""scikit-learn conventions for ratfit's estimators, without depending on scikit-learn.

scikit-learn (BSD-3, GPL-compatible) stays an optional package: the protocol
it reads (``get_params``/``set_params``, ``predict``/``score``, its tags) is
written here, so ``import ratfit`` needs neither it nor its dependencies, and
``clone``, ``cross_val_score``, grid searches and pipelines work when it is
installed. Its tags are built from scikit-learn itself, only when it asks.

Parameters are the keyword arguments of ``__init__`` (read from the signature of
every class in the MRO that forwards ``**params`` upwards), stored unchanged as
attributes; ``fit`` validates them and never writes them back. That is what
``sklearn.base.clone``, grid searches and pipelines rely on.
"""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ratfit.core.options import SEGMENT_OPTIONS
from ratfit.core.segments import Segments
from ratfit.errors import InputError

__all__ = ["Estimator", "Regressor", "r2_score"]


class Estimator:
    """Mixin: ``get_params`` / ``set_params`` / ``__repr__`` from ``__init__``'s signature.

    Examples
    --------
    >>> from ratfit import RationalFitter
    >>> RationalFitter(basis="chebyshev", max_total=30)
    RationalFitter(basis='chebyshev', max_total=30)
    >>> RationalFitter().set_params(solver="daqp").get_params()["solver"]
    'daqp'
    """

    @classmethod
    def _param_defaults(cls) -> dict[str, Any]:
        """Every constructor parameter with its default (the most derived class wins)."""
        out: dict[str, Any] = {}
        for klass in cls.__mro__:
            init = klass.__dict__.get("__init__")
            if init is None:
                continue
            if klass is object:
                break
            forwards = False
            for p in inspect.signature(init).parameters.values():
                if p.name == "self":
                    continue
                if p.kind is p.VAR_KEYWORD:
                    forwards = True
                elif p.kind is p.VAR_POSITIONAL:
                    raise TypeError(f"{cls.__name__}.__init__ must not take *args")
                else:
                    out.setdefault(p.name, p.default)
            if not forwards:
                break
        return out

    @classmethod
    def _get_param_names(cls) -> list[str]:
        return sorted(cls._param_defaults())

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor parameters of this estimator.

        Parameters
        ----------
        deep : bool, default True
            Also return the parameters of nested estimators as ``name__param``.

        Returns
        -------
        dict
            Parameter name -> value, exactly as given to ``__init__`` or ``set_params``.
        """
        out: dict[str, Any] = {}
        for name in self._get_param_names():
            value = getattr(self, name)
            out[name] = value
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                for k, v in value.get_params(deep=True).items():
                    out[f"{name}__{k}"] = v
        return out

    def set_params(self, **params: Any) -> Estimator:
        """Set constructor parameters (``name__param`` reaches nested estimators).

        Returns
        -------
        self
        """
        valid = self._get_param_names()
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, sep, sub = key.partition("__")
            if name not in valid:
                raise InputError(
                    f"unknown parameter {name!r} for {type(self).__name__}; "
                    f"valid: {', '.join(valid)}"
                )
            if sep:
                nested.setdefault(name, {})[sub] = value
            else:
                setattr(self, name, value)
        for name, sub_params in nested.items():
            getattr(self, name).set_params(**sub_params)
        return self

    def __repr__(self) -> str:
        defaults = self._param_defaults()
        shown = [
            f"{name}={getattr(self, name)!r}"
            for name in defaults
            if not _same(getattr(self, name), defaults[name])
        ]
        return f"{type(self).__name__}({', '.join(shown)})"


class Regressor(Estimator):
    """Mixin: a regressor to scikit-learn (its tags; ``score`` is R^2 of ``predict``),
    and the segments ``fit(X, y)`` builds from the ``dt`` / ``abs_width`` parameters."""

    _estimator_type = "regressor"  # how scikit-learn < 1.6 recognises a regressor
    # the segment widths fit(X, y) builds segments with (both regressors take them)
    dt: float | None
    abs_width: float | None

    def segments_of(self, X: ArrayLike | Segments, y: ArrayLike | None = None) -> Segments:
        """The segments ``fit(X, y)`` fits: ``X`` itself when it is a
        :class:`~ratfit.core.segments.Segments`, else built from ``y`` with ``dt``
        and/or ``abs_width``. Combinations that cannot mean anything are refused."""
        widths = [f"{k}={getattr(self, k)!r}" for k in SEGMENT_OPTIONS
                  if getattr(self, k) is not None]
        if isinstance(X, Segments):
            if y is not None:
                raise InputError("fit(segments, y): Segments carry their own bounds; "
                                 "give y only with an array X")
            if widths:
                raise InputError(
                    f"{', '.join(widths)} builds segments from fit(X, y), but fit() got "
                    "Segments with bounds of their own: leave dt and abs_width at None")
            return X
        if y is None:
            raise InputError(
                f"fit() got {type(X).__name__} without y: give fit(X, y) with "
                f"{type(self).__name__}(dt=...) or abs_width=..., or fit(Segments)")
        if not widths:
            raise InputError(
                f"fit(X, y) builds segments around y from the width options: give "
                f"{type(self).__name__}(dt=...) (relative) and/or abs_width=... (absolute)")
        return Segments.from_widths(X, y, dt=self.dt, abs_width=self.abs_width)


    def predict(self, X: ArrayLike) -> Any:  # pragma: no cover - every subclass has one
        raise NotImplementedError

    def score(self, X: ArrayLike, y: ArrayLike) -> float:
        """R^2 of ``predict(X)`` against ``y`` (:func:`r2_score`; 1.0 is exact): what
        scikit-learn regressors return, so its model selection ranks ratfit fits like
        any other. It measures closeness to y, not whether the segments are met (a
        fit's ``verification`` says that)."""
        return r2_score(y, self.predict(X))

    def __sklearn_tags__(self) -> Any:
        """scikit-learn >= 1.6 asks this (only it calls it, so it is importable)."""
        from sklearn.utils import InputTags, RegressorTags, Tags, TargetTags

        return Tags(estimator_type="regressor",
                    target_tags=TargetTags(required=True, multi_output=True),
                    regressor_tags=RegressorTags(), input_tags=InputTags(one_d_array=True))


def _same(a: Any, b: Any) -> bool:
    """Whether a parameter still holds its default (arrays and lists compared by value)."""
    if a is b:
        return True
    if type(a) is not type(b) and not (isinstance(a, (int, float)) and isinstance(b, (int, float))
                                       and not isinstance(a, bool) and not isinstance(b, bool)):
        return False
    try:
        return bool(np.array_equal(np.asarray(a, dtype=object), np.asarray(b, dtype=object)))
    except Exception:  # noqa: BLE001 -- an uncomparable value is simply "not the default"
        return False


def r2_score(y_true: ArrayLike, y_pred: ArrayLike) -> float:
    """Coefficient of determination R^2 = 1 - SS_res / SS_tot, averaged over outputs.

    scikit-learn's ``r2_score`` with its defaults (uniform average; an output
    whose true values are constant scores 1.0 when predicted exactly, else 0.0),
    written here so that ratfit's ``score`` needs no scikit-learn. 1.0 is a
    perfect prediction; a constant prediction of the mean scores 0.0.
    """
    yt = np.asarray(y_true, dtype=float)
    yp = np.asarray(y_pred, dtype=float)
    yt = yt.reshape(yt.shape[0], -1)
    yp = yp.reshape(yp.shape[0], -1)
    if yt.shape != yp.shape:
        raise InputError(f"y has shape {yt.shape}, the prediction {yp.shape}")
    res = ((yt - yp) ** 2).sum(axis=0)
    tot = ((yt - yt.mean(axis=0)) ** 2).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(tot > 0, 1.0 - res / np.where(tot > 0, tot, 1.0),
                       np.where(res == 0, 1.0, 0.0))
    return float(per.mean())
