"""tribo: the oscillating tribometer's runs, records, fits and catalog in Python.

Built from the same Rust crates as the ``tribo`` command: a fit or an explanation here is the
command's ``--json`` object, to the last digit.

>>> import tribo
>>> run = tribo.open_run("demo-out/runs/<run>")        # numpy float64 arrays in SI units
>>> run.t, run.x, run.v, run.ft, run.temp, run.ecr
>>> f = tribo.fit(run, law="coulomb-viscous")
>>> f.mu, f.mu_se, f.verdict
>>> tribo.catalog("demo-out/runs").runs(status="complete").to_pandas()

Errors are exceptions a script can catch, all subclasses of :class:`TriboError`:
:class:`NotAnalysable` (nothing to fit), :class:`IncompleteRun` (a run with holes; its
``missing_blocks``), :class:`RecordError` (a record that cannot be read; its ``file``, ``line``,
``column``), :class:`UsageError` (a wrong argument: an unknown law or effect, a value out of
range; a ``ValueError`` too).
"""

from __future__ import annotations

import datetime
import json
import os
from typing import (
    Any,
    Dict,
    Iterator,
    List,
    Literal,
    Optional,
    Sequence,
    Tuple,
    Union,
    overload,
)

import numpy as np

import functools

from . import _tribo
from ._tribo import IncompleteRun, NotAnalysable, RecordError, TriboError


class UsageError(TriboError, ValueError):
    """A wrong argument (an unknown law or effect, a value out of range): a :class:`TriboError`
    like every error of the package, and a ``ValueError`` as Python's own are."""


def _usage(f):
    """Raises the ``ValueError`` of a wrong argument as :class:`UsageError`."""

    @functools.wraps(f)
    def wrapped(*args, **kwargs):
        try:
            return f(*args, **kwargs)
        except TriboError:
            raise
        except ValueError as e:
            raise UsageError(str(e)) from None

    return wrapped

__version__: str = _tribo.__version__

__all__ = [
    "Record",
    "Run",
    "Fit",
    "Explanation",
    "Step",
    "Catalog",
    "RunTable",
    "open_run",
    "read_record",
    "simulate",
    "fit",
    "explain",
    "catalog",
    "export_parquet",
    "TriboError",
    "NotAnalysable",
    "IncompleteRun",
    "RecordError",
    "UsageError",
]

PathLike = Union[str, "os.PathLike[str]"]

#: The sample columns, their names in tables (with their unit) and their units.
COLUMNS: Tuple[Tuple[str, str, str], ...] = (
    ("t", "t_s", "s"),
    ("x", "x_m", "m"),
    ("v", "v_m_s", "m/s"),
    ("ft", "ft_n", "N"),
    ("temp", "temp_c", "°C"),
    ("ecr", "ecr_ohm", "Ω"),
)


class Record:
    """A record's samples as numpy float64 arrays (SI units: s, m, m/s, N, °C, Ω).

    ``ft``, ``temp`` and ``ecr`` are ``None`` when the record has no such column. For a
    dimensionless record (``units == "dimensionless"``), ``t, x, v`` are ``tau, y, y'``.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    ft: Optional[np.ndarray]
    temp: Optional[np.ndarray]
    ecr: Optional[np.ndarray]
    #: ``(mass_kg, stiffness_n_per_m, load_n)``, or None when the record gives none.
    rig: Optional[Tuple[float, float, float]]
    units: str
    #: The file the record was read from (None for a simulated record).
    path: Optional[str]
    force_cutoff_hz: Optional[float]

    def __init__(self, d: Dict[str, Any]):
        self.path = d["path"]
        self.units = d.get("units", "si")
        self.rig = tuple(d["rig"]) if d.get("rig") is not None else None  # type: ignore[assignment]
        self.force_cutoff_hz = d.get("force_cutoff_hz")
        for name, _, _ in COLUMNS:
            setattr(self, name, d[name])

    def __len__(self) -> int:
        return len(self.t)

    def __repr__(self) -> str:
        return f"<tribo.{type(self).__name__} {self.path or '(in memory)'}: {len(self)} samples>"

    def columns(self) -> Dict[str, np.ndarray]:
        """The columns present, by their table name (``t_s``, ``x_m``, ``v_m_s``, ``ft_n``, …)."""
        si = self.units == "si"
        out: Dict[str, np.ndarray] = {}
        for (name, col, _), alt in zip(COLUMNS, ("tau", "y", "ydot", "ft_n", "temp_c", "ecr_ohm")):
            a = getattr(self, name)
            if a is not None:
                out[col if si else alt] = a
        return out

    def to_pandas(self) -> Any:
        """A ``pandas.DataFrame`` with one row per sample (needs pandas)."""
        import pandas as pd

        return pd.DataFrame(self.columns(), copy=False)

    def to_polars(self) -> Any:
        """A ``polars.DataFrame`` with one row per sample (needs polars)."""
        import polars as pl

        return pl.DataFrame(self.columns())

    def _fit_args(self) -> Dict[str, Any]:
        if self.path is not None:
            return {"path": self.path}
        c = lambda a: None if a is None else np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
        return {
            "t": c(self.t),
            "x": c(self.x),
            "v": c(self.v),
            "ft": c(self.ft),
            "temp": c(self.temp),
            "ecr": c(self.ecr),
            "rig": self.rig,
            "dimensionless": self.units == "dimensionless",
            "stated_cutoff_hz": self.force_cutoff_hz,
        }


class Run(Record):
    """A stored run, its samples on the sample grid: index ``i`` is sample ``i`` of the run.

    Where a sample is missing (an acquisition gap the rig reported, a block not received, a
    damaged stretch of the log) every channel is NaN and ``mask`` is True; ``t`` is always the
    sample's time. ``gaps`` are the rig's acquisition gaps as ``(first_sample, count)``,
    ``ecr_changes`` its ECR range changes as ``(first_sample, range, settling_samples)``.
    """

    mask: np.ndarray
    ecr_range: Optional[np.ndarray]
    ecr_settling: Optional[np.ndarray]
    gaps: List[Tuple[int, int]]
    ecr_changes: List[Tuple[int, int, int]]
    missing_blocks: List[int]
    complete: bool
    completeness: str
    status: str
    recovery: Optional[str]
    #: The run's metadata (meta.toml) as a dict.
    meta: Dict[str, Any]
    #: The stored results: ``{"onboard": {...}, "host": {...}, ...}``.
    results: Dict[str, Any]
    sample_rate_hz: float

    def __init__(self, d: Dict[str, Any]):
        super().__init__(d)
        self.mask = d["mask"]
        self.ecr_range = d["ecr_range"]
        self.ecr_settling = d["ecr_settling"]
        self.gaps = [tuple(g) for g in d["gaps"]]  # type: ignore[misc]
        self.ecr_changes = [tuple(c) for c in d["ecr_changes"]]  # type: ignore[misc]
        self.missing_blocks = list(d["missing_blocks"])
        self.complete = d["complete"]
        self.completeness = d["completeness"]
        self.status = d["status"]
        self.recovery = d["recovery"]
        self.meta = json.loads(d["meta"])
        self.results = json.loads(d["results"])
        self.sample_rate_hz = d["sample_rate_hz"]

    @property
    def onboard(self) -> Optional[Dict[str, Any]]:
        """The rig's on-board result (μ0, μ1 and their ±), or None."""
        return self.results.get("onboard")

    @property
    def host(self) -> Optional[Dict[str, Any]]:
        """The host's fit stored with the run, or None."""
        return self.results.get("host")

    def columns(self) -> Dict[str, np.ndarray]:
        out = super().columns()
        out["missing"] = self.mask
        if self.ecr_range is not None:
            out["ecr_range"] = self.ecr_range
            out["ecr_settling"] = self.ecr_settling  # type: ignore[assignment]
        return out

    def to_parquet(self, output: PathLike) -> int:
        """Writes the run as ``tribo export --format parquet`` does; returns the rows written."""
        return export_parquet(self, output)


def _float(v: Any) -> float:
    """A JSON number as a float (``null``, a NaN or an infinity written by the CLI, is NaN)."""
    return float("nan") if v is None else float(v)


def _opt_float(v: Any) -> Optional[float]:
    return None if v is None else float(v)


class _Result:
    """A result: its main fields as typed attributes, the command's ``--json`` object in
    :attr:`json` (and :meth:`to_dict`); any other field of it is reachable as an attribute or
    ``result["field"]`` too."""

    def __init__(self, j: Union[str, Dict[str, Any]]):
        #: The object as a dict, exactly the command's ``--json``.
        self.json: Dict[str, Any] = json.loads(j) if isinstance(j, str) else j

    def to_dict(self) -> Dict[str, Any]:
        """The command's ``--json`` object as a dict (a copy), for a script to store or send."""
        return json.loads(json.dumps(self.json))

    def __getattr__(self, name: str) -> Any:
        try:
            return self.__dict__["json"][name]
        except KeyError:
            raise AttributeError(
                f"{type(self).__name__} has no field {name!r}; its fields: {', '.join(self.json)}"
            ) from None

    def __getitem__(self, name: str) -> Any:
        return self.json[name]

    def __contains__(self, name: str) -> bool:
        return name in self.json

    def __dir__(self) -> List[str]:
        return sorted(set(super().__dir__()) | set(self.json))


class Fit(_Result):
    """A friction-law fit: ``tribo fit --json``'s object, its fields typed.

    ``law``, ``verdict`` (adequate / inadequate / not-converged), ``mu`` and ``mu_se`` (the
    dimensionless constants and their standard errors), ``p_si`` and ``p_si_se`` (SI
    coefficients of μ(v) = Σ p_j v^j), ``gap`` and ``noise_floor`` (relative to the initial
    amplitude), ``half_cycles``, ``converged``, ``record``, ``rig`` (the constants used and where
    each came from), ``defaults``, ``cross_check`` (the on-board result beside it), ``channels``
    (whether the velocity is the displacement's derivative), an apparatus record's ``mu_a``,
    ``windows`` when asked for; ``span`` and the rest as in the JSON.
    """

    #: The law fitted (``coulomb-viscous``, ``quadratic``, …).
    law: str
    #: ``adequate``, ``inadequate`` or ``not-converged``.
    verdict: str
    #: Whether the fit converged.
    converged: bool
    #: The dimensionless constants μ0, μ1, … in order of j (NaN where the CLI wrote null).
    mu: List[float]
    #: Their standard errors (None where unknown).
    mu_se: List[Optional[float]]
    #: The SI coefficients of μ(v) = Σ p_j v^j.
    p_si: List[float]
    #: Their standard errors (None where unknown).
    p_si_se: List[Optional[float]]
    #: The envelope's misfit, relative to the initial amplitude.
    gap: float
    #: The record's noise floor, relative to the initial amplitude.
    noise_floor: float
    #: Half cycles the fit used.
    half_cycles: Optional[int]
    #: The record fitted (its path or name); None in an explanation's ``base_fit``.
    record: Optional[str]
    #: The rig constants used and where each came from (None in an explanation's ``base_fit``).
    rig: Optional[Dict[str, Any]]
    #: The constants a default stood in for.
    defaults: List[str]
    #: The on-board result beside the host's, ``{"unavailable": why}``, or None for a law the rig
    #: does not fit.
    cross_check: Optional[Dict[str, Any]]
    #: The velocity column against the displacement's derivative over the first cycles:
    #: ``gain``, ``r2``, ``samples``, ``half_cycles``, ``consistent`` (False: swapped input
    #: cables suspected); None for too little motion (or in an explanation's ``base_fit``).
    channels: Optional[Dict[str, Any]]
    #: An apparatus record's (load 0) damping μ_a and its standard error, else None.
    mu_a: Optional[float]
    mu_a_se: Optional[float]
    #: The fits over windows of the record, when asked for (``windows=N``).
    windows: Optional[List[Dict[str, Any]]]

    def __init__(self, j: Union[str, Dict[str, Any]]):
        super().__init__(j)
        d = self.json
        self.law = str(d["law"])
        self.verdict = str(d["verdict"])
        self.converged = bool(d.get("converged", False))
        self.mu = [_float(m) for m in d["mu"]]
        self.mu_se = [_opt_float(s) for s in d["mu_se"]]
        self.p_si = [_float(p) for p in d.get("p_si", [])]
        self.p_si_se = [_opt_float(s) for s in d.get("p_si_se", [])]
        self.gap = _float(d.get("gap"))
        self.noise_floor = _float(d.get("noise_floor"))
        self.half_cycles = d.get("half_cycles")
        self.record = d.get("record")
        self.rig = d.get("rig")
        self.defaults = list(d.get("defaults", []))
        self.cross_check = d.get("cross_check")
        self.channels = d.get("channels")
        self.mu_a = _opt_float(d.get("mu_a"))
        self.mu_a_se = _opt_float(d.get("mu_a_se"))
        self.windows = d.get("windows")

    def __repr__(self) -> str:
        mu = ", ".join(
            f"{m:.6g} ± {s:.2g}" if s is not None else f"{m:.6g} ± ?"
            for m, s in zip(self.mu, self.mu_se)
        )
        return f"<tribo.Fit {self.law}: mu = [{mu}], {self.verdict}>"


class Step(_Result):
    """One effect an explanation added: ``effect``, the gap before and after it, the
    parameters it recovered and their standard errors (None where the fit cannot tell)."""

    #: The effect's name (``quadratic-velocity``, ``stribeck``, …).
    effect: str
    #: The gap of the model before adding it, and after adding it and refitting.
    gap_before: float
    gap_after: float
    #: Its recovered parameters (dimensionless and SI) and their standard errors.
    params: Dict[str, float]
    params_se: Dict[str, Optional[float]]

    def __init__(self, j: Union[str, Dict[str, Any]]):
        super().__init__(j)
        d = self.json
        self.effect = str(d["effect"])
        self.gap_before = _float(d["gap_before"])
        self.gap_after = _float(d["gap_after"])
        self.params = {k: _float(v) for k, v in d.get("params", {}).items()}
        self.params_se = {k: _opt_float(v) for k, v in d.get("params_se", {}).items()}

    def __repr__(self) -> str:
        return f"<tribo.Step {self.effect}: gap {self.gap_before:.3g} → {self.gap_after:.3g}>"


class Explanation(_Result):
    """What a law misses in a record: ``tribo explain --json``'s object, its fields typed.

    ``conclusion``, ``base`` and ``base_fit`` (``tribo fit``'s result for the base law, a
    :class:`Fit`), ``steps`` (each effect added, a :class:`Step`), ``gap_initial``,
    ``gap_final``, ``noise_floor``, ``unexplained_fraction``, ``missing_effects``,
    ``ambiguous``, ``force_cutoff_hz``, ``cross_check``; the models, rounds and diagnostics as
    in the JSON.
    """

    #: What the explanation concludes (``base-adequate``, ``explained``, …).
    conclusion: str
    #: The base law.
    base: str
    #: The base law's fit (``tribo fit``'s estimator).
    base_fit: Fit
    #: The effects added, in order.
    steps: List[Step]
    #: The gap of the base law, and of the final model.
    gap_initial: float
    gap_final: float
    #: The record's noise floor (relative to the initial amplitude).
    noise_floor: float
    #: The part of the base law's misfit the final model leaves unexplained.
    unexplained_fraction: float
    #: The effects the record shows and no step explained.
    missing_effects: List[str]
    #: Effects the record cannot tell apart.
    ambiguous: List[str]
    #: The force channel's low-pass cut-off used (Hz), or None.
    force_cutoff_hz: Optional[float]
    #: The on-board result beside the base fit (as in :attr:`Fit.cross_check`).
    cross_check: Optional[Dict[str, Any]]

    def __init__(self, j: Union[str, Dict[str, Any]]):
        super().__init__(j)
        d = self.json
        self.conclusion = str(d["conclusion"])
        self.base = str(d["base"])
        self.base_fit = Fit(d["base_fit"])
        self.steps = [Step(s) for s in d.get("steps", [])]
        self.gap_initial = _float(d["gap_initial"])
        self.gap_final = _float(d["gap_final"])
        self.noise_floor = _float(d["noise_floor"])
        self.unexplained_fraction = _float(d.get("unexplained_fraction"))
        self.missing_effects = list(d.get("missing_effects", []))
        self.ambiguous = list(d.get("ambiguous", []))
        self.force_cutoff_hz = _opt_float(d.get("force_cutoff_hz"))
        self.cross_check = d.get("cross_check")

    def __repr__(self) -> str:
        steps = ", ".join(s.effect for s in self.steps) or "no effect added"
        return f"<tribo.Explanation {self.base}: {self.conclusion} ({steps})>"


class RunTable:
    """Runs of the catalog: one row per run (the fields of ``tribo runs --json`` and more).

    ``len(table)``, ``table[i]`` (a row as a dict), ``table["load_n"]`` (a column as a list),
    iteration over rows, ``to_pandas()``, ``to_polars()``. ``damaged`` lists run folders whose
    log is damaged (never hidden): ``{"path", "status": "damaged", "why"}``.
    """

    def __init__(self, runs: List[Dict[str, Any]], damaged: List[Dict[str, Any]]):
        self.rows = runs
        self.damaged = damaged

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[Dict[str, Any]]:
        return iter(self.rows)

    def __getitem__(self, key: Union[int, str]) -> Any:
        if isinstance(key, str):
            return [r[key] for r in self.rows]
        return self.rows[key]

    def __repr__(self) -> str:
        return f"<tribo.RunTable: {len(self)} runs, {len(self.damaged)} damaged>"

    @property
    def columns(self) -> List[str]:
        return list(self.rows[0]) if self.rows else []

    def to_pandas(self) -> Any:
        import pandas as pd

        return pd.DataFrame(self.rows)

    def to_polars(self) -> Any:
        import polars as pl

        return pl.DataFrame(self.rows, infer_schema_length=None)


class Catalog:
    """The run catalog of a store (its SQLite index, rebuilt when it lags the run folders)."""

    def __init__(self, store: PathLike):
        self.store = os.fspath(store)

    def runs(
        self,
        status: Optional[str] = None,
        load: Union[None, float, Tuple[float, float], str] = None,
        temp: Union[None, float, Tuple[float, float], str] = None,
        campaign: Optional[str] = None,
        label: Optional[str] = None,
        rig: Optional[str] = None,
        since: Union[None, str, datetime.date] = None,
        until: Union[None, str, datetime.date] = None,
        reindex: bool = False,
    ) -> RunTable:
        """The runs matching every filter given, as ``tribo runs`` selects them.

        ``status``: complete, incomplete, aborted, recording or damaged. ``load`` (N) and
        ``temp`` (°C): a value (matches ±0.0005 N, ±0.5 °C, as the CLI), a ``(lo, hi)`` range or
        the CLI's ``"0.1..0.4"``. ``campaign``: its name; ``label``: a substring; ``rig``: the
        rig's serial number. ``since`` and ``until``: the first and last day (UTC, both
        included) the runs were taken, a ``datetime.date`` or ``"YYYY-MM-DD"``; a damaged run,
        whose day is not known, is then left out, as with every filter but ``status``.
        """
        text = _tribo.catalog_runs(
            self.store,
            status=status,
            load=_range(load, 5e-4),
            temp=_range(temp, 0.5),
            campaign=campaign,
            label=label,
            rig=rig,
            since=_day(since),
            until=_day(until),
            reindex=reindex,
        )
        j = json.loads(text)
        return RunTable(j["runs"], j["damaged"])

    def to_parquet(self, output: PathLike) -> int:
        """Writes the catalog as ``tribo export --catalog --format parquet``; returns the rows."""
        return _tribo.export_catalog_parquet(self.store, os.fspath(output))


def _day(v: Union[None, str, datetime.date]) -> Optional[str]:
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, datetime.datetime):
        raise TypeError("since/until take a day (datetime.date or 'YYYY-MM-DD'), not a datetime")
    return v.isoformat()


def _range(v: Any, tol: float) -> Optional[Tuple[float, float]]:
    if v is None:
        return None
    if isinstance(v, str):
        if ".." in v:
            a, b = v.split("..", 1)
            return float(a), float(b)
        v = float(v)
    if isinstance(v, (int, float)):
        return float(v) - tol, float(v) + tol
    lo, hi = v
    return float(lo), float(hi)


@_usage
def open_run(path: PathLike, allow_incomplete: bool = False) -> Run:
    """Opens a run folder of the store: its samples as numpy arrays, metadata and results.

    A run with holes (blocks not received, a damaged log) raises :class:`IncompleteRun` naming
    what is missing, unless ``allow_incomplete=True``: then what is held is opened, NaN and
    ``mask`` True where a sample is missing. Acquisition gaps the rig reported are part of a
    complete run: their samples are NaN with ``mask`` True too.
    """
    return Run(_tribo.open_run(os.fspath(path), allow_incomplete=allow_incomplete))


@_usage
def read_record(path: PathLike) -> Record:
    """Reads a CSV record (``t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]`` with ``# mass_kg=…`` lines,
    or ``tau,y,ydot``). A malformed file raises :class:`RecordError` with ``file``, ``line``
    and ``column``."""
    return Record(_tribo.read_record(os.fspath(path)))


@_usage
def simulate(**flags: Any) -> Record:
    """A simulated record, the one ``tribo sim`` makes with these options (Python names, e.g.
    ``law="quadratic", mu=[0.02, 0.01, 0.005], noise=True, duration_s=2, held_s=0.5``).

    ``tribo sim --help`` lists the options and their defaults; an option left out or None keeps
    its default, an unknown one is a ValueError.
    """
    options: Dict[str, Any] = {}
    for k, v in flags.items():
        if v is None:
            continue
        if isinstance(v, (list, tuple, np.ndarray)):
            v = [float(x) for x in v]
        elif isinstance(v, np.generic):
            v = v.item()
        options[k] = v
    return Record(_tribo.simulate(json.dumps(options)))


Source = Union[PathLike, Record]


def _source(src: Source) -> Dict[str, Any]:
    if isinstance(src, Record):
        return src._fit_args()
    return {"path": os.fspath(src)}


Sources = Union[List[Source], Tuple[Source, ...]]


@overload
def fit(
    record: Source,
    law: str = ...,
    *,
    mass_kg: Optional[float] = ...,
    stiffness: Optional[float] = ...,
    load_n: Optional[float] = ...,
    apparatus_mu1: float = ...,
    windows: int = ...,
    longest_clean_stretch: bool = ...,
    errors: Literal["raise", "keep"] = ...,
) -> Fit: ...
@overload
def fit(
    record: Sources,
    law: str = ...,
    *,
    mass_kg: Optional[float] = ...,
    stiffness: Optional[float] = ...,
    load_n: Optional[float] = ...,
    apparatus_mu1: float = ...,
    windows: int = ...,
    longest_clean_stretch: bool = ...,
    errors: Literal["raise"] = ...,
) -> List[Fit]: ...
@overload
def fit(
    record: Sources,
    law: str = ...,
    *,
    mass_kg: Optional[float] = ...,
    stiffness: Optional[float] = ...,
    load_n: Optional[float] = ...,
    apparatus_mu1: float = ...,
    windows: int = ...,
    longest_clean_stretch: bool = ...,
    errors: Literal["keep"],
) -> List[Union[Fit, Exception]]: ...
@_usage
def fit(
    record: Union[Source, Sources],
    law: str = "coulomb-viscous",
    *,
    mass_kg: Optional[float] = None,
    stiffness: Optional[float] = None,
    load_n: Optional[float] = None,
    apparatus_mu1: float = 0.0,
    windows: int = 0,
    longest_clean_stretch: bool = False,
    errors: str = "raise",
) -> Any:
    """Fits a friction law (coulomb, viscous, coulomb-viscous, quadratic, poly:N, lugre) to a
    record or run, as ``tribo fit --json`` does: the same estimator, the same numbers.

    ``record`` is a path (run folder or CSV), a :class:`Run` or a :class:`Record`. Raises
    :class:`NotAnalysable` when nothing can be fitted, :class:`IncompleteRun` for a run with
    holes (``longest_clean_stretch=True`` fits the longest stretch without one). The GIL is
    released while fitting.

    ``record`` may also be a list (or tuple) of them: they are fitted on every core, each on one
    thread, and a list of :class:`Fit` comes back in the same order, each what ``fit`` of that
    record alone gives. A record that cannot be fitted raises its error (the first in the list's
    order, after all are fitted) unless ``errors="keep"``, which puts the exception in its place.
    """
    if errors not in ("raise", "keep"):
        raise ValueError(f'errors must be "raise" or "keep", got {errors!r}')
    if isinstance(record, (list, tuple)):
        out = _tribo.fit_many(
            [_source(r) for r in record],
            law=law,
            mass_kg=mass_kg,
            stiffness=stiffness,
            load_n=load_n,
            apparatus_mu1=apparatus_mu1,
            windows=windows,
            longest_clean_stretch=longest_clean_stretch,
        )
        if errors == "raise":
            for r in out:
                if isinstance(r, BaseException):
                    raise r
        return [r if isinstance(r, BaseException) else Fit(r) for r in out]
    return Fit(
        _tribo.fit(
            **_source(record),
            law=law,
            mass_kg=mass_kg,
            stiffness=stiffness,
            load_n=load_n,
            apparatus_mu1=apparatus_mu1,
            windows=windows,
            longest_clean_stretch=longest_clean_stretch,
        )
    )


@_usage
def explain(
    record: Source,
    base: str = "coulomb-viscous",
    *,
    only: Optional[Sequence[str]] = None,
    max_steps: int = 3,
    force_cutoff_hz: Optional[float] = None,
    longest_clean_stretch: bool = False,
) -> Explanation:
    """Finds what ``base`` misses in a record, as ``tribo explain --json`` does. The GIL is
    released while it works."""
    return Explanation(
        _tribo.explain(
            **_source(record),
            base=base,
            only=list(only) if only is not None else None,
            max_steps=max_steps,
            force_cutoff_hz=force_cutoff_hz,
            longest_clean_stretch=longest_clean_stretch,
        )
    )


def catalog(store: Optional[PathLike] = None) -> Catalog:
    """The catalog of a run store (default: ``$TRIBO_STORE``, else ``./runs``)."""
    if store is None:
        store = os.environ.get("TRIBO_STORE", "runs")
    return Catalog(store)


def export_parquet(source: Union[PathLike, Run, Record], output: PathLike) -> int:
    """Writes a run folder or CSV record as Parquet, as ``tribo export --format parquet``;
    returns the rows written. (For a run opened with holes, what the folder holds is written.)"""
    if isinstance(source, Record):
        if source.path is None:
            raise TriboError("a simulated record has no file to export: save it first")
        source = source.path
    return _tribo.export_parquet(os.fspath(source), os.fspath(output))
