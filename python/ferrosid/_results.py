"""Typed result objects over the command line's JSON reports.

Each result keeps the exact JSON text the library produced (the same serialiser as
``ferrosid ... --json``): ``to_json()`` returns it unchanged and ``to_dict()`` parses it (Python
parses the shortest round-trip floats exactly, so every number equals the library's value).
"""
from __future__ import annotations

import html
import json
from typing import Any, Dict, List, Optional

import numpy as np


class Result:
    """A report: ``to_dict()``, ``to_json()``, item access to its top-level fields."""

    kind = "report"

    def __init__(self, json_text: str):
        self._json = json_text
        self._dict: Optional[Dict[str, Any]] = None

    def to_json(self) -> str:
        """The JSON text, byte for byte what the command line prints with ``--json``."""
        return self._json

    def to_dict(self) -> Dict[str, Any]:
        """The report as plain Python data (a fresh copy)."""
        return json.loads(self._json)

    @property
    def _d(self) -> Dict[str, Any]:
        if self._dict is None:
            self._dict = json.loads(self._json)
        return self._dict

    def __getitem__(self, key: str) -> Any:
        return self._d[key]

    def keys(self):
        return self._d.keys()

    def __repr__(self) -> str:
        return f"<ferrosid {self.kind}: {', '.join(list(self._d.keys())[:8])}>"

    def _repr_html_(self) -> str:
        rows = "".join(
            f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(_short(v))}</td></tr>"
            for k, v in self._d.items()
        )
        return f"<b>ferrosid {html.escape(self.kind)}</b><table>{rows}</table>"


def _short(v: Any) -> str:
    s = json.dumps(v)
    return s if len(s) <= 120 else s[:117] + "..."


class Model:
    """A discrete state-space model x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k] at sample
    time ``ts`` seconds (the ``model.json`` of the command line)."""

    def __init__(self, data: Dict[str, Any]):
        self.data = data
        self.A = np.array(data["a"], dtype=float).reshape(len(data["a"]), -1)
        self.B = np.array(data["b"], dtype=float).reshape(self.A.shape[0], -1)
        self.C = np.array(data["c"], dtype=float).reshape(-1, self.A.shape[0])
        self.D = np.array(data["d"], dtype=float).reshape(self.C.shape[0], self.B.shape[1])
        self.ts = float(data["ts"])

    def to_dict(self) -> Dict[str, Any]:
        return json.loads(json.dumps(self.data))

    def to_control(self):
        """A ``control.StateSpace`` (python-control, optional dependency)."""
        try:
            import control  # type: ignore
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError(
                "Model.to_control() needs the optional package python-control "
                "(pip install control)"
            ) from e
        return control.ss(self.A, self.B, self.C, self.D, self.ts)

    @classmethod
    def from_control(cls, sys) -> "Model":
        """From a discrete ``control.StateSpace`` (dt > 0)."""
        dt = getattr(sys, "dt", None)
        if not dt or dt is True:
            raise ValueError("a discrete-time model with a numeric sample time dt is required")
        return cls(
            {
                "a": np.asarray(sys.A, dtype=float).tolist(),
                "b": np.asarray(sys.B, dtype=float).tolist(),
                "c": np.asarray(sys.C, dtype=float).tolist(),
                "d": np.asarray(sys.D, dtype=float).tolist(),
                "ts": float(dt),
            }
        )

    def __repr__(self) -> str:
        return f"<ferrosid Model order {self.A.shape[0]}, ts {self.ts} s>"


class FrfResult(Result):
    """``ferrosid frf --json``: one estimate per (input, output) pair."""

    kind = "frequency response"

    @property
    def estimates(self) -> List[Dict[str, Any]]:
        return self._d["estimates"]

    def _est(self, i: int) -> Dict[str, Any]:
        return self.estimates[i]

    def freq_hz(self, i: int = 0) -> np.ndarray:
        return np.asarray(self._est(i)["freq_hz"], dtype=float)

    def h(self, i: int = 0) -> np.ndarray:
        """Complex H at each bin (output units per input unit)."""
        e = self._est(i)
        return np.asarray(e["re"], dtype=float) + 1j * np.asarray(e["im"], dtype=float)

    def coherence(self, i: int = 0) -> np.ndarray:
        return np.asarray(self._est(i)["coherence"], dtype=float)


class IdentifyResult(Result):
    """``ferrosid identify --json``: the model, order selection and validation."""

    kind = "identification"

    @property
    def model(self) -> Model:
        """The model with its operating point: the content of ``model.json`` as ``ferrosid
        identify --out`` writes it (what :func:`ferrosid.gap` needs to read the logs as
        recorded)."""
        data = dict(self._d["n4sid"]["model"])
        if self._d.get("operating_point") is not None:
            data.setdefault("operating_point", self._d["operating_point"])
        return Model(data)


class PipelineResult(Result):
    """``ferrosid run``: the receipts document (``receipts.json``, the JSON of ``ferrosid run
    --json``) with the run kept for the report, the model file and the firmware header."""

    kind = "pipeline run"

    def __init__(self, native):
        super().__init__(native.receipts_json())
        self._native = native

    @property
    def all_pass(self) -> bool:
        return bool(self._native.all_pass)

    @property
    def model(self) -> Model:
        return Model(json.loads(self._native.model_json()))

    def model_json(self) -> str:
        """``model.json`` as ``ferrosid run`` writes it."""
        return self._native.model_json()

    def report_html(self) -> str:
        """``report.html``: the self-contained report with inline SVG figures."""
        return self._native.report_html()

    def figures(self):
        """The report's figures: list of (name, caption, SVG text)."""
        return self._native.figures()

    def summary_text(self) -> str:
        return self._native.summary_text()

    def write_outputs(self, out=None):
        """Writes the output directory as ``ferrosid run --out DIR``; returns its path."""
        return self._native.write_outputs(out)

    def codegen(self, prefix: str = "ferrosid"):
        """(C header, Rust module) of the run's model, PID, W_m and receipts."""
        return self._native.codegen(prefix)

    def section(self, name: str) -> Any:
        return self._d.get(name)

    def _repr_html_(self) -> str:
        return self.report_html()


class AuditResult(Result):
    """The dual-amplitude nonlinearity audit (the pipeline's audit stage): ``to_dict()`` is
    the ``audit`` section of ``receipts.json``; ``receipts`` the audit's receipts (gain shift,
    phase shift, coherence near crossover) as the pipeline issues them."""

    kind = "nonlinearity audit"

    def __init__(self, json_text: str, receipts_json: str):
        super().__init__(json_text)
        self.receipts: List[Dict[str, Any]] = json.loads(receipts_json)

    @property
    def verdict(self) -> str:
        """``linear_enough`` or ``not_linear``."""
        return self._d["verdict"]

    @property
    def linear_enough(self) -> bool:
        return self.verdict == "linear_enough"


class WeightResult(Result):
    """The multiplicative uncertainty weight W_m (the pipeline's uncertainty stage):
    ``to_dict()`` is the ``uncertainty_weight`` section of ``receipts.json``; pass the result to
    :func:`ferrosid.tune_pid`. ``weight`` is the full fit (envelope, overbound ratios)."""

    kind = "uncertainty weight"

    def __init__(self, json_text: str, weight_json: str):
        super().__init__(json_text)
        self._weight_json = weight_json

    def weight_json(self) -> str:
        """The fitted weight as the library serialises it (what tune_pid reads back)."""
        return self._weight_json

    @property
    def weight(self) -> Dict[str, Any]:
        return json.loads(self._weight_json)

    @property
    def num(self) -> np.ndarray:
        """Numerator, descending powers of s (s in rad/s)."""
        return np.asarray(self._d["num"], dtype=float)

    @property
    def den(self) -> np.ndarray:
        """Denominator, descending powers of s, monic."""
        return np.asarray(self._d["den"], dtype=float)

    def magnitude(self, f_hz) -> np.ndarray:
        """|W_m(j 2π f)| at the frequencies ``f_hz`` (Hz)."""
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)
        return np.abs(np.polyval(self.num, s) / np.polyval(self.den, s))


class ControllerResult(Result):
    """The robust PID (the pipeline's tuning stage): ``to_dict()`` is the ``controller``
    section of ``receipts.json`` (continuous gains, the discrete firmware law, the design
    point with its achieved margins)."""

    kind = "robust PID"

    @property
    def pid(self) -> Dict[str, Any]:
        return self._d["pid"]

    @property
    def discrete(self) -> Optional[Dict[str, Any]]:
        return self._d["discrete"]

    @property
    def design(self) -> Dict[str, Any]:
        return self._d["design"]

    @property
    def crossover_hz(self) -> float:
        """The achieved design crossover, Hz."""
        return float(self._d["design"]["crossover_hz"])


class GapResult(Result):
    """The sim-to-real gap diagnosis: ``to_dict()`` is the report of ``ferrosid gap --json``
    (the pipeline's ``gap_diagnosis.report``)."""

    kind = "gap diagnosis"

    @property
    def verdict(self) -> str:
        return self._d["verdict"]


class FleetSummary(Result):
    """``ferrosid fleet --json``: units, distributions across units, outliers."""

    kind = "fleet summary"

    def _repr_html_(self) -> str:
        head = "<tr><th>serial</th><th>status</th><th>receipts</th><th>dc gain</th></tr>"
        rows = "".join(
            f"<tr><td>{html.escape(u['serial'])}</td><td>{u['status']}</td>"
            f"<td>{u['passed']}/{u['receipts']}</td><td>{u['dc_gain']}</td></tr>"
            for u in self._d["units"]
        )
        return f"<b>ferrosid fleet</b><table>{head}{rows}</table>"
