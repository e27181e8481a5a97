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
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple, Union

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


class _Json:
    """A result object: the command's ``--json`` object, its fields as attributes."""

    def __init__(self, text: str):
        #: The object as a dict, exactly the command's ``--json``.
        self.json: Dict[str, Any] = json.loads(text)

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


class Fit(_Json):
    """A friction-law fit: ``tribo fit --json``'s fields as attributes.

    ``law``, ``verdict`` (adequate / inadequate / not-converged), ``mu`` and ``mu_se`` (the
    dimensionless constants and their standard errors), ``p_si`` and ``p_si_se`` (SI
    coefficients of μ(v) = Σ p_j v^j), ``gap`` and ``noise_floor`` (relative to the initial
    amplitude), ``span``, ``cross_check`` (the on-board result beside it), ``rig``, ``record``…
    """

    @property
    def law(self) -> str:
        """The law fitted (``coulomb-viscous``, ``quadratic``, …)."""
        return self.json["law"]

    @property
    def verdict(self) -> str:
        """``adequate``, ``inadequate`` or ``not-converged``."""
        return self.json["verdict"]

    @property
    def mu(self) -> List[float]:
        """The dimensionless constants μ0, μ1, … in order of j."""
        return self.json["mu"]

    @property
    def mu_se(self) -> List[Optional[float]]:
        """Their standard errors (None where unknown)."""
        return self.json["mu_se"]

    @property
    def gap(self) -> float:
        """The envelope's misfit, relative to the initial amplitude."""
        return self.json["gap"]

    @property
    def noise_floor(self) -> float:
        """The record's noise floor, relative to the initial amplitude."""
        return self.json["noise_floor"]

    def __repr__(self) -> str:
        mu = ", ".join(f"{m:.6g} ± {s:.2g}" for m, s in zip(self.json["mu"], self.json["mu_se"]))
        return f"<tribo.Fit {self.json['law']}: mu = [{mu}], {self.json['verdict']}>"


class Explanation(_Json):
    """What a law misses in a record: ``tribo explain --json``'s fields as attributes.

    ``base_fit`` (``tribo fit``'s result), ``steps`` (each effect added and the gap after it),
    ``gap_base``, ``gap_final``, ``noise_floor``, ``effects``, ``cross_check``…
    """

    def __repr__(self) -> str:
        return f"<tribo.Explanation: {', '.join(self.json)}>"


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


@_usage
def fit(
    record: Source,
    law: str = "coulomb-viscous",
    *,
    mass_kg: Optional[float] = None,
    stiffness: Optional[float] = None,
    load_n: Optional[float] = None,
    apparatus_mu1: float = 0.0,
    windows: int = 0,
    longest_clean_stretch: bool = False,
) -> Fit:
    """Fits a friction law (coulomb, viscous, coulomb-viscous, quadratic, poly:N, lugre) to a
    record or run, as ``tribo fit --json`` does: the same estimator, the same numbers.

    ``record`` is a path (run folder or CSV), a :class:`Run` or a :class:`Record`. Raises
    :class:`NotAnalysable` when nothing can be fitted, :class:`IncompleteRun` for a run with
    holes (``longest_clean_stretch=True`` fits the longest stretch without one). The GIL is
    released while fitting.
    """
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
