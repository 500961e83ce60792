"""The functions of the package: argument checking and conversion in Python, the work in the
library (``ferrosid._native``), typed results out."""
from __future__ import annotations

import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._results import FleetSummary, FrfResult, IdentifyResult, PipelineResult

ArrayLike = Any


def _samples(x: ArrayLike, what: str) -> np.ndarray:
    """A 1-D float64 array of samples from numpy, pandas or a sequence; TypeError for a
    non-numeric dtype, ValueError for a shape that is not 1-D."""
    if hasattr(x, "to_numpy"):  # pandas Series / Index
        x = x.to_numpy()
    try:
        a = np.asarray(x)
    except Exception as e:  # ragged lists and the like
        raise TypeError(f"{what}: not an array of samples ({e})") from None
    if a.dtype.kind not in "iuf":
        raise TypeError(
            f"{what}: expected real numbers (a float or integer array), got dtype {a.dtype}"
        )
    if a.ndim != 1:
        raise ValueError(
            f"{what}: expected a 1-D array of samples, got shape {a.shape}"
            + (" (give one channel per argument)" if a.ndim == 2 else "")
        )
    return np.ascontiguousarray(a, dtype=np.float64)


def _name(x: ArrayLike, given: Optional[str], default: str) -> str:
    if given is not None:
        return str(given)
    n = getattr(x, "name", None)
    return str(n) if isinstance(n, str) and n else default


def _fs(fs: Any) -> float:
    if isinstance(fs, (bool, np.bool_)) or not isinstance(fs, (int, float, np.integer, np.floating)):
        raise TypeError(f"fs: expected a sample rate in Hz (a number), got {type(fs).__name__}")
    return float(fs)


def _sample_time(fs, ts) -> float:
    """ts in seconds from fs (Hz) or ts; a value that is not finite and positive is a
    UsageError (exit code 2), as the CLI's --fs."""
    v = _fs(fs if fs is not None else ts)
    if not (np.isfinite(v) and v > 0.0):
        what = "sample rate fs (Hz)" if fs is not None else "sample time ts (s)"
        err = _native.UsageError(f"{what} must be a finite positive number, got {v}")
        err.category, err.exit_code = "usage", 2
        raise err
    return 1.0 / v if fs is not None else v


class Log:
    """One SISO log: input ``u`` and output ``y`` sampled at ``fs`` Hz (or every ``ts``
    seconds). ``name`` stands for the file name in reports and error messages. From a
    DataFrame: ``Log.from_frame(df, "u", "y", fs)``; from a file, with the command line's
    readers: ``Log.read(path, input="u", output="y")``."""

    def __init__(
        self,
        u: ArrayLike,
        y: ArrayLike,
        fs: Optional[float] = None,
        name: str = "<array>",
        input_name: Optional[str] = None,
        output_name: Optional[str] = None,
        *,
        ts: Optional[float] = None,
    ):
        self.u = _samples(u, "u")
        self.y = _samples(y, "y")
        if (fs is None) == (ts is None):
            raise TypeError("give the sample rate fs (Hz) or the sample time ts (s), not both")
        self.ts = _sample_time(fs, ts)
        self.name = str(name)
        self.input_name = _name(u, input_name, "u")
        self.output_name = _name(y, output_name, "y")
        self.warnings: List[str] = []

    @property
    def fs(self) -> float:
        return 1.0 / self.ts

    @classmethod
    def from_frame(cls, df, input: str, output: str, fs: float, name: str = "<dataframe>"):
        for c in (input, output):
            if c not in df.columns:
                raise KeyError(f"column {c!r} not in the frame (columns: {list(df.columns)})")
        return cls(df[input], df[output], fs, name=name, input_name=input, output_name=output)

    @classmethod
    def read(
        cls,
        path: Union[str, os.PathLike],
        input: str = "u",
        output: str = "y",
        fs: Optional[float] = None,
        time: Optional[str] = None,
        time_scale: Optional[float] = None,
    ) -> "Log":
        """Reads a CSV, ``.mat`` or text log with the command line's readers and checks
        (``--input``, ``--output``, ``--fs``, ``--time``, ``--time-scale``)."""
        p = os.fspath(path)
        ts, ins, outs, warnings = _native.read_log(p, [input], [output], fs, time, time_scale)
        log = cls(ins[0][1], outs[0][1], name=p, input_name=ins[0][0], output_name=outs[0][0], ts=ts)
        log.warnings = list(warnings)
        return log

    def _native(self) -> Tuple[str, float, list, list]:
        return (self.name, self.ts, [(self.input_name, self.u)], [(self.output_name, self.y)])


LogsArg = Union[Log, Sequence[Log], ArrayLike]


def _logs(u_or_logs: LogsArg, y, fs, name, input_name, output_name) -> List[Log]:
    if isinstance(u_or_logs, Log):
        return [u_or_logs]
    if isinstance(u_or_logs, (list, tuple)) and u_or_logs and all(
        isinstance(l, Log) for l in u_or_logs
    ):
        return list(u_or_logs)
    if y is None or fs is None:
        raise TypeError("give u, y and fs (arrays and a sample rate in Hz), or Log objects")
    return [Log(u_or_logs, y, fs, name, input_name, output_name)]


_FRF_KEYS = ("nperseg", "overlap", "window", "detrend", "period", "skip_periods", "gate")


def frf(
    u: LogsArg,
    y: Optional[ArrayLike] = None,
    fs: Optional[float] = None,
    *,
    name: str = "<array>",
    input_name: Optional[str] = None,
    output_name: Optional[str] = None,
    **options,
) -> FrfResult:
    """Empirical frequency response with coherence gating (``ferrosid frf``).

    ``u``, ``y``: 1-D arrays (or pandas Series) sampled at ``fs`` Hz, or one or more
    :class:`Log`. Options as the command line: ``nperseg``, ``overlap``, ``window`` (hann,
    hamming, blackman, boxcar), ``detrend`` (constant, linear, none), ``period``,
    ``skip_periods``, ``gate``.
    """
    logs = _logs(u, y, fs, name, input_name, output_name)
    unknown = set(options) - set(_FRF_KEYS)
    if unknown:
        raise TypeError(f"frf() got unknown options {sorted(unknown)}; known: {list(_FRF_KEYS)}")
    return FrfResult(_native.frf([l._native() for l in logs], options))


def identify(
    u: LogsArg,
    y: Optional[ArrayLike] = None,
    fs: Optional[float] = None,
    *,
    validate: Optional[Union[Log, Tuple[ArrayLike, ArrayLike]]] = None,
    name: str = "<array>",
    input_name: Optional[str] = None,
    output_name: Optional[str] = None,
    etfe: Optional[Dict[str, Any]] = None,
    **options,
) -> IdentifyResult:
    """N4SID with order selection, continuous equivalent and validation (``ferrosid
    identify``). Options as the command line's flags: ``order``, ``order_range=(min, max)``,
    ``block_rows``, ``no_d``, ``d_auto``, ``stable_margin``, ``weighting``, ``remove``,
    ``decimate``, ``crossover_hz``, ``phase_tol``, ``max_lag``, ``structure``, ``known``;
    ``etfe``: the frf options of the validation estimate. ``validate``: a :class:`Log` or
    ``(u, y)`` at the same rate."""
    logs = _logs(u, y, fs, name, input_name, output_name)
    v = None
    if validate is not None:
        if not isinstance(validate, Log):
            vu, vy = validate
            validate = Log(
                vu, vy, None, "<validation>", logs[0].input_name, logs[0].output_name, ts=logs[0].ts
            )
        v = validate._native()
    return IdentifyResult(
        _native.identify([l._native() for l in logs], v, etfe=etfe, **options)
    )


def run_pipeline(path: Union[str, os.PathLike]) -> PipelineResult:
    """The whole chain of a PIPELINE.toml (``ferrosid run``, without writing files; see
    :meth:`PipelineResult.write_outputs`)."""
    return PipelineResult(_native.run_pipeline(os.fspath(path)))


def _run(pipeline) -> PipelineResult:
    return pipeline if isinstance(pipeline, PipelineResult) else run_pipeline(pipeline)


def receipts(pipeline) -> Dict[str, Any]:
    """The receipts (verdict and every receipt) of a pipeline (path or result)."""
    d = _run(pipeline).to_dict()
    return {k: d[k] for k in ("all_pass", "receipts") if k in d}


def _section(pipeline, *names: str):
    d = _run(pipeline).to_dict()
    for n in names:
        if n in d:
            return d[n]
    raise KeyError(f"the receipts document has none of {names}; keys: {list(d)}")


def audit(pipeline):
    """The nonlinearity audit of a pipeline's runs (the pipeline's audit stage)."""
    return _section(pipeline, "audit")


def fit_wm(pipeline):
    """The multiplicative uncertainty weight W_m fitted by the pipeline (its envelope and
    coefficients)."""
    return _section(pipeline, "uncertainty_weight")


def tune_pid(pipeline):
    """The robust PID the pipeline tuned (gains, discretisation, achieved margins)."""
    return _section(pipeline, "controller")


def gap(pipeline):
    """The pipeline's sim-to-real gap diagnosis of its model."""
    return _section(pipeline, "gap_diagnosis")


def codegen(pipeline, prefix: str = "ferrosid") -> Tuple[str, str]:
    """(C header, Rust module) for the firmware from a pipeline run."""
    return _run(pipeline).codegen(prefix)


# --- fleets ---------------------------------------------------------------------------------


def fleet_units(dir: Union[str, os.PathLike]) -> Tuple[str, List[str]]:
    """(layout, serial numbers) of a fleet directory, as ``ferrosid fleet`` finds them."""
    return _native.fleet_units(os.fspath(dir))


def fleet_unit(dir, template, layout: str, serial: str, physical: Optional[Dict] = None) -> Dict:
    """The pipeline on one unit (a pure function of the files: map it on any engine)."""
    return _native.fleet_unit(os.fspath(dir), os.fspath(template), layout, serial, physical)


def fleet_summary(template, layout: str, units: Iterable[Dict]) -> FleetSummary:
    """The fleet summary of unit results (any order), equal to ``ferrosid fleet --json``."""
    return FleetSummary(_native.fleet_summary(os.fspath(template), layout, list(units)))
