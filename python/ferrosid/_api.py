"""The functions of the package: argument checking and conversion in Python, the work in the
library (``ferrosid._native``), typed results out."""
from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._results import (
    AuditResult,
    ControllerResult,
    FleetSummary,
    FrfResult,
    GapResult,
    IdentifyResult,
    Model,
    PipelineResult,
    WeightResult,
)

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


def _number(v: Any, what: str) -> float:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"{what}: expected a number, got {type(v).__name__}")
    return float(v)


def _fs(fs: Any) -> float:
    return _number(fs, "fs (a sample rate in Hz)")


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


# --- the pipeline's stages on arrays -----------------------------------------------------------
#
# audit / fit_wm / tune_pid / gap take logs as numpy arrays (or Log objects) and call the
# pipeline's own stage functions (ferrosid::pipeline::arrays in the library): the same numbers
# as `ferrosid run` on the same logs and settings. Settings are the keys of a PIPELINE.toml's
# sections ([preprocess], [etfe], [audit], [uncertainty], [control]) with the file's defaults.
# Given a pipeline (a PipelineResult or the path of a PIPELINE.toml) instead of logs, each
# returns the pipeline's section as a plain dict.

_PREPROCESS_KEYS = ("remove", "decimate")
_ETFE_KEYS = ("nperseg", "overlap", "window", "coherence_gate")
_AUDIT_KEYS = (
    "band_factor",
    "max_gain_shift_db",
    "max_phase_shift_deg",
    "min_coherence",
    "coherence_band_factor",
)
_UNCERTAINTY_KEYS = ("order", "min_level", "family", "beyond_band_level", "below_band_level")
_CONTROL_KEYS = (
    "crossover_hz",
    "actuator_limit",
    "ms_max",
    "reference_amplitude",
    "integral",
    "derivative",
    "rolloff_ratio",
    "rolloff_zeta",
    "min_crossover_scale",
    "limit_control_effort",
)


def _is_pipeline(x) -> bool:
    return isinstance(x, (PipelineResult, str, os.PathLike))


def _sections(values: Dict[str, Any], **sections: Sequence[str]) -> Dict[str, Dict[str, Any]]:
    """{section: {key: value}} of the keys given (None: the pipeline file's default)."""
    out: Dict[str, Dict[str, Any]] = {}
    for sec, keys in sections.items():
        d = {k: values[k] for k in keys if values.get(k) is not None}
        if d:
            out[sec] = d
    return out


def _as_log(what: str, v, fs, ts: Optional[float] = None) -> Log:
    """A Log from a Log, or (u, y) / (u, y, amplitude) arrays at fs Hz (named `what`)."""
    if isinstance(v, Log):
        return v
    if isinstance(v, (tuple, list)) and len(v) in (2, 3):
        if fs is None and ts is None:
            raise TypeError(f"{what}: (u, y) arrays need the sample rate fs (Hz)")
        if fs is not None:
            return Log(v[0], v[1], fs, name=what)
        return Log(v[0], v[1], name=what, ts=ts)
    raise TypeError(
        f"{what}: expected a ferrosid.Log or a tuple (u, y) or (u, y, amplitude) of arrays, "
        f"got {type(v).__name__}"
    )


def _runs(func: str, runs, named: Dict[str, Any], fs) -> List[Tuple[str, Optional[float], Log]]:
    """[(name, amplitude, Log)] of the runs, given as a mapping name -> run or as keyword
    arguments name=run; a run is a Log, (Log, amplitude), (u, y) or (u, y, amplitude)."""
    if runs is not None and named:
        raise TypeError(f"{func}(): give the runs as a mapping or as keywords, not both")
    if runs is None:
        runs = named
    if not hasattr(runs, "items"):
        raise TypeError(
            f"{func}(): the runs must be keyword arguments name=(u, y[, amplitude]) or a "
            f"mapping of them, got {type(runs).__name__}"
        )
    out = []
    for name, v in runs.items():
        amplitude = None
        if isinstance(v, (tuple, list)) and len(v) == 2 and isinstance(v[0], Log):
            v, amplitude = v  # (Log, amplitude)
        elif isinstance(v, (tuple, list)) and len(v) == 3:
            amplitude = v[2]
        if amplitude is not None:
            amplitude = _number(amplitude, f"{name}: amplitude")
        out.append((str(name), amplitude, _as_log(str(name), v, fs)))
    if not out:
        raise TypeError(f"{func}(): no run given (e.g. low=(u1, y1), high=(u2, y2))")
    return out


def _native_runs(runs) -> list:
    return [(n, a, l._native()) for n, a, l in runs]


def _model_json(model) -> str:
    """JSON text of a model file from a Model, an identify or pipeline result, a dict
    ({a, b, c, d, ts[, operating_point]} or {num, den, ts}), JSON text or a discrete
    python-control StateSpace."""
    if isinstance(model, (IdentifyResult, PipelineResult)):
        model = model.model
    if isinstance(model, Model):
        return json.dumps(model.data)
    if isinstance(model, dict):
        return json.dumps(model)
    if isinstance(model, str):
        return model
    if all(hasattr(model, k) for k in ("A", "B", "C", "D", "dt")):
        return json.dumps(Model.from_control(model).data)
    raise TypeError(
        "model: expected a ferrosid.Model (e.g. identify(...).model), an identify or pipeline "
        f"result, a model dict or JSON text, or a control.StateSpace; got {type(model).__name__}"
    )


def audit(
    runs=None,
    fs: Optional[float] = None,
    *,
    crossover_hz: Optional[float] = None,
    band_factor: Optional[float] = None,
    max_gain_shift_db: Optional[float] = None,
    max_phase_shift_deg: Optional[float] = None,
    min_coherence: Optional[float] = None,
    coherence_band_factor: Optional[float] = None,
    remove: Optional[str] = None,
    decimate: Optional[int] = None,
    nperseg: Optional[int] = None,
    overlap: Optional[int] = None,
    window: Optional[str] = None,
    coherence_gate: Optional[float] = None,
    **named_runs,
):
    """The dual-amplitude nonlinearity audit (the pipeline's audit stage): do the runs' ETFEs
    agree within ``max_gain_shift_db`` / ``max_phase_shift_deg`` in the band
    [f_c/band_factor, f_c·band_factor] around ``crossover_hz``?

        ferrosid.audit(low=(u1, y1, 0.05), high=(u2, y2, 0.15), fs=1000, crossover_hz=8)

    Runs as keywords or a mapping ``name -> Log | (u, y) | (u, y, amplitude)`` (amplitude in
    input units; default the input RMS after preprocessing), two or more. The keys of
    ``[audit]``, ``[etfe]`` and ``[preprocess]`` with the pipeline file's defaults. Returns an
    :class:`AuditResult` (``to_dict()``: the ``audit`` section of ``receipts.json``;
    ``receipts``: the audit's receipts). Given a pipeline (result or path) instead, its
    ``audit`` section as a dict."""
    if isinstance(runs, (Model, IdentifyResult)):
        raise TypeError(
            "audit() compares the runs' frequency responses with each other and takes no "
            "model: audit(low=(u1, y1), high=(u2, y2), fs=..., crossover_hz=...)"
        )
    if _is_pipeline(runs) and not named_runs:
        return _section(runs, "audit")
    if crossover_hz is None:
        raise TypeError("audit(): crossover_hz (Hz) is required: the audit band is around it")
    rs = _runs("audit", runs, named_runs, fs)
    settings = _sections(
        locals(), preprocess=_PREPROCESS_KEYS, etfe=_ETFE_KEYS, audit=_AUDIT_KEYS
    )
    summary, rec = _native.audit(_native_runs(rs), _number(crossover_hz, "crossover_hz"), settings)
    return AuditResult(summary, rec)


def fit_wm(
    model=None,
    runs=None,
    fs: Optional[float] = None,
    *,
    validation=None,
    order: Optional[int] = None,
    min_level: Optional[float] = None,
    family: Optional[Sequence[str]] = None,
    beyond_band_level: Optional[float] = None,
    below_band_level: Optional[float] = None,
    remove: Optional[str] = None,
    decimate: Optional[int] = None,
    nperseg: Optional[int] = None,
    overlap: Optional[int] = None,
    window: Optional[str] = None,
    coherence_gate: Optional[float] = None,
    **named_runs,
):
    """The multiplicative uncertainty weight W_m (the pipeline's uncertainty stage): the
    relative spread of the runs' (and the validation log's) ETFEs around ``model`` at the bins
    where every one passes the coherence gate, overbounded by a stable minimum-phase W_m.

        wm = ferrosid.fit_wm(model, low=(u1, y1), high=(u2, y2), validation=(u3, y3), fs=1000)

    ``model``: the discrete model at the logs' rate (``identify(...).model``, a model dict,
    ...). Runs as for :func:`audit`; ``validation``: a Log or (u, y). The keys of
    ``[uncertainty]``, ``[etfe]`` and ``[preprocess]``. Returns a :class:`WeightResult`
    (``to_dict()``: the ``uncertainty_weight`` section; pass it to :func:`tune_pid`). Given a
    pipeline instead of a model, its ``uncertainty_weight`` section as a dict."""
    if _is_pipeline(model) and runs is None and not named_runs:
        return _section(model, "uncertainty_weight")
    if model is None:
        raise TypeError("fit_wm(): the model is required (e.g. identify(...).model)")
    rs = _runs("fit_wm", runs, named_runs, fs)
    v = None
    if validation is not None:
        v = _as_log("validation", validation, fs, ts=rs[0][2].ts)._native()
    if family is not None:
        family = [str(f) for f in family]
    settings = _sections(
        locals(),
        preprocess=_PREPROCESS_KEYS,
        etfe=_ETFE_KEYS,
        uncertainty=_UNCERTAINTY_KEYS,
    )
    summary, weight = _native.fit_wm(_model_json(model), _native_runs(rs), v, settings)
    return WeightResult(summary, weight)


def tune_pid(
    model=None,
    wm=None,
    *,
    crossover_hz: Optional[float] = None,
    actuator_limit: Optional[float] = None,
    ms_max: Optional[float] = None,
    reference_amplitude: Optional[float] = None,
    integral: Optional[bool] = None,
    derivative: Optional[bool] = None,
    rolloff_ratio: Optional[float] = None,
    rolloff_zeta: Optional[float] = None,
    min_crossover_scale: Optional[float] = None,
    limit_control_effort: Optional[bool] = None,
):
    """The robust PID (the pipeline's tuning stage): the highest crossover up to
    ``crossover_hz`` meeting M_s <= ``ms_max``, ‖W_m T‖∞ < 1 (with ``wm``) and
    ‖KS‖∞·reference_amplitude <= ``actuator_limit``.

        pid = ferrosid.tune_pid(model, wm, crossover_hz=8, actuator_limit=0.3,
                                reference_amplitude=5, rolloff_ratio=4)

    ``model``: the discrete model; ``wm``: a :class:`WeightResult` from :func:`fit_wm` (None:
    robust stability unconstrained). The keys of ``[control]`` with the pipeline file's
    defaults (``crossover_hz`` and ``actuator_limit`` required). Returns a
    :class:`ControllerResult` (``to_dict()``: the ``controller`` section); no controller
    meeting the requirements raises :class:`NumericalError` with the reason. Given a pipeline
    instead of a model, its ``controller`` section as a dict."""
    if _is_pipeline(model) and wm is None and crossover_hz is None:
        return _section(model, "controller")
    if model is None:
        raise TypeError("tune_pid(): the model is required (e.g. identify(...).model)")
    if wm is not None and not isinstance(wm, WeightResult):
        raise TypeError(f"wm: expected the WeightResult of fit_wm(), got {type(wm).__name__}")
    for k in ("crossover_hz", "actuator_limit"):
        if locals()[k] is None:
            raise TypeError(f"tune_pid(): {k} is required (the [control] key of a pipeline file)")
    control = _sections(locals(), control=_CONTROL_KEYS)["control"]
    return ControllerResult(
        _native.tune_pid(_model_json(model), control, None if wm is None else wm.weight_json())
    )


def gap(
    model=None,
    runs=None,
    fs: Optional[float] = None,
    *,
    validation=None,
    margin: Optional[float] = None,
    threshold: float = 0.2,
    gate: Optional[float] = None,
    warmup: Optional[int] = None,
    nperseg: Optional[int] = None,
    effects: Optional[Sequence[str]] = None,
    **named_runs,
):
    """The sim-to-real gap diagnosis (``ferrosid gap``; the pipeline's gap stage): where the
    model and the logs as recorded disagree and which unmodelled effect (friction, backlash,
    dead zone, saturation, delay, resonance, quantisation) explains it.

        g = ferrosid.gap(model, low=(u1, y1), high=(u2, y2), validation=(u3, y3), fs=1000)

    ``model``: with its operating point when identified from the logs (``identify(...).model``
    carries it), as ``model.json``; the runs train, ``validation`` (required) ranks. Options as
    ``ferrosid gap``: ``margin``, ``threshold``, ``gate``, ``warmup``, ``nperseg``,
    ``effects``. Returns a :class:`GapResult` (``to_dict()``: the ``ferrosid gap --json``
    report, the pipeline's ``gap_diagnosis.report``). Given a pipeline instead of a model, its
    ``gap_diagnosis`` section as a dict."""
    if _is_pipeline(model) and runs is None and not named_runs:
        return _section(model, "gap_diagnosis")
    if model is None:
        raise TypeError("gap(): the model is required (e.g. identify(...).model)")
    if validation is None:
        raise TypeError("gap(): validation=(u, y) is required: the diagnosis ranks on fresh data")
    rs = _runs("gap", runs, named_runs, fs)
    for n, a, _ in rs:
        if a is not None:
            raise TypeError(f"gap(): run {n!r}: give (u, y) (the diagnosis takes no amplitude)")
    v = _as_log("validation", validation, fs, ts=rs[0][2].ts)
    return GapResult(
        _native.gap(
            _model_json(model),
            [l._native() for _, _, l in rs],
            v._native(),
            margin=margin,
            threshold=threshold,
            gate=gate,
            warmup=warmup,
            nperseg=nperseg,
            effects=[str(e) for e in (effects or [])],
        )
    )


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
