"""Type stubs of the Rust extension (`python/src/`: errors, runs, fits, catalog); use the `tribo`
package's API. `fit` and `explain` return the CLI's `--json` text, which the package wraps in its
typed `Fit` and `Explanation` (with `Step`) classes."""

from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

__version__: str

class TriboError(Exception):
    """Any failure of tribo; the message says what went wrong and what to do next."""

class NotAnalysable(TriboError):
    """Nothing can be fitted (no oscillation, too few half cycles, saturation, a non-finite sample:
    `reason` "non-finite", a record not plausible as written: `reason` None)."""

    reason: Optional[str]

class IncompleteRun(TriboError):
    """A run with holes (blocks not received, a damaged log)."""

    path: str
    missing_blocks: List[int]

class RecordError(TriboError):
    """A record that cannot be read."""

    file: Optional[str]
    line: Optional[int]
    column: Optional[int]

def open_run(path: str, allow_incomplete: bool = False) -> Dict[str, Any]: ...
def read_record(path: str) -> Dict[str, Any]: ...
def simulate(options: str) -> Dict[str, Any]: ...
def fit(
    path: Optional[str] = None,
    *,
    law: str = "coulomb-viscous",
    mass_kg: Optional[float] = None,
    stiffness: Optional[float] = None,
    load_n: Optional[float] = None,
    apparatus_mu1: float = 0.0,
    windows: int = 0,
    longest_clean_stretch: bool = False,
    t: Optional[np.ndarray] = None,
    x: Optional[np.ndarray] = None,
    v: Optional[np.ndarray] = None,
    ft: Optional[np.ndarray] = None,
    temp: Optional[np.ndarray] = None,
    ecr: Optional[np.ndarray] = None,
    rig: Optional[Tuple[float, float, float]] = None,
    dimensionless: bool = False,
    name: Optional[str] = None,
    stated_cutoff_hz: Optional[float] = None,
) -> str: ...
def fit_many(
    sources: List[Dict[str, Any]],
    *,
    law: str = "coulomb-viscous",
    mass_kg: Optional[float] = None,
    stiffness: Optional[float] = None,
    load_n: Optional[float] = None,
    apparatus_mu1: float = 0.0,
    windows: int = 0,
    longest_clean_stretch: bool = False,
) -> List[Union[str, Exception]]: ...
def explain(
    path: Optional[str] = None,
    *,
    base: str = "coulomb-viscous",
    only: Optional[List[str]] = None,
    max_steps: int = 3,
    force_cutoff_hz: Optional[float] = None,
    longest_clean_stretch: bool = False,
    t: Optional[np.ndarray] = None,
    x: Optional[np.ndarray] = None,
    v: Optional[np.ndarray] = None,
    ft: Optional[np.ndarray] = None,
    temp: Optional[np.ndarray] = None,
    ecr: Optional[np.ndarray] = None,
    rig: Optional[Tuple[float, float, float]] = None,
    dimensionless: bool = False,
    name: Optional[str] = None,
    stated_cutoff_hz: Optional[float] = None,
) -> str: ...
def catalog_runs(
    store: str,
    *,
    status: Optional[str] = None,
    load: Optional[Tuple[float, float]] = None,
    temp: Optional[Tuple[float, float]] = None,
    campaign: Optional[str] = None,
    label: Optional[str] = None,
    rig: Optional[str] = None,
    since: Optional[str] = None,
    until: Optional[str] = None,
    reindex: bool = False,
) -> str: ...
def export_parquet(source: str, output: str) -> int: ...
def export_catalog_parquet(store: str, output: str) -> int: ...
