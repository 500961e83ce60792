"""ferrosid for Python: system identification with receipts, on the same library as the
``ferrosid`` command line.

numpy arrays (or pandas Series / DataFrame columns) in, typed results out. Every result has
``to_dict()`` and ``to_json()`` equal to the command line's ``--json`` output, renders in
Jupyter (``_repr_html_``), and errors are :class:`FerrosidError` subclasses whose
``category`` and ``exit_code`` match the command line's exit status (2 usage, 3 data,
4 numerical). The numeric work runs without the GIL.

    >>> import numpy as np, ferrosid
    >>> r = ferrosid.frf(u, y, fs=1000.0)            # Welch H1 + coherence (ferrosid frf)
    >>> m = ferrosid.identify(u, y, fs=1000.0, validate=(u2, y2))   # ferrosid identify
    >>> a = ferrosid.audit(low=(u1, y1, 0.05), high=(u2, y2, 0.15), fs=1000.0, crossover_hz=8.0)
    >>> wm = ferrosid.fit_wm(m.model, low=(u1, y1), high=(u2, y2), validation=(u3, y3), fs=1000.0)
    >>> pid = ferrosid.tune_pid(m.model, wm, crossover_hz=8.0, actuator_limit=0.3)
    >>> g = ferrosid.gap(m.model, low=(u1, y1), high=(u2, y2), validation=(u3, y3), fs=1000.0)
    >>> run = ferrosid.run_pipeline("examples/pipeline.toml")       # ferrosid run
    >>> run.receipts, run.audit, run.weight, run.controller, run.physical, run.gap
"""
from __future__ import annotations

from ._native import (  # noqa: F401  (re-exported)
    DataError,
    FerrosidError,
    NumericalError,
    UsageError,
    __version__,
)
from ._results import (  # noqa: F401
    AuditResult,
    ControllerResult,
    FleetSummary,
    GapResult,
    WeightResult,
    FrfResult,
    IdentifyResult,
    Model,
    PipelineResult,
    Result,
)
from ._api import (  # noqa: F401
    Log,
    audit,
    codegen,
    fit_wm,
    fleet_summary,
    fleet_unit,
    fleet_units,
    frf,
    gap,
    identify,
    receipts,
    run_pipeline,
    tune_pid,
)

__all__ = [
    "FerrosidError",
    "DataError",
    "UsageError",
    "NumericalError",
    "Log",
    "Result",
    "FrfResult",
    "IdentifyResult",
    "Model",
    "PipelineResult",
    "FleetSummary",
    "AuditResult",
    "WeightResult",
    "ControllerResult",
    "GapResult",
    "frf",
    "identify",
    "run_pipeline",
    "receipts",
    "audit",
    "fit_wm",
    "tune_pid",
    "gap",
    "codegen",
    "fleet_units",
    "fleet_unit",
    "fleet_summary",
]
