"""Builds the peer-benchmark table from the JSON results of the three tools.

Usage: python3 bench/peers/compare.py WORKDIR OUT.md

Reads WORKDIR/{ferrosid,python,octave}.json (any missing tool is reported as such) and writes the
markdown table to OUT.md and stdout. Frequency-response errors are computed here, with numpy,
against the true ZOH plant of plant.py.
"""
import json
import os
import platform
import sys

import numpy as np

import plant


def load(path):
    if not os.path.exists(path):
        return None
    with open(path) as fh:
        return json.load(fh)


def siso(model, n):
    """Normalises matrices (Octave's jsonencode flattens vectors) to SISO shapes."""
    return {
        "a": np.reshape(np.asarray(model["a"], dtype=float), (n, n)),
        "b": np.reshape(np.asarray(model["b"], dtype=float), (n, 1)),
        "c": np.reshape(np.asarray(model["c"], dtype=float), (1, n)),
        "d": np.reshape(np.asarray(model["d"], dtype=float), (1, 1)),
    }


def order(model):
    return int(np.asarray(model["a"], dtype=float).size ** 0.5 + 0.5)


def cpu_name():
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def fmt_t(s):
    return "%.1f ms" % (1e3 * s) if s < 10 else "%.2f s" % s


def main():
    work, out = sys.argv[1], sys.argv[2]
    fe = load(os.path.join(work, "ferrosid.json"))
    py = load(os.path.join(work, "python.json"))
    oc = load(os.path.join(work, "octave.json"))
    proc = load(os.path.join(work, "process.json"))
    rows = []
    n4 = {}
    if fe:
        m = siso(fe["model"], order(fe["model"]))
        n4["ferrosid"] = (fe["n4sid_order3_seconds"], plant.frf_errors(m))
        ma = siso(fe["model_auto"], order(fe["model_auto"]))
        n4["ferrosid_auto"] = (fe["n4sid_auto_seconds"], plant.frf_errors(ma), fe["auto_order"])
        mn = siso(fe["model_no_d"], order(fe["model_no_d"]))
        n4["ferrosid_no_d"] = (fe["n4sid_no_d_seconds"], plant.frf_errors(mn))
    if oc:
        m = siso(oc, order(oc))
        n4["slicot"] = (oc["seconds"], plant.frf_errors(m))
    if py:
        m = siso(py["sippy_model"], order(py["sippy_model"]))
        n4["sippy"] = (py["sippy_n4sid_seconds"], plant.frf_errors(m))

    lines = []
    lines.append(
        "Reference case (bench/peers/plant.py): 100,000-sample SISO log of G(s) = a wn^2 / "
        "((s + a)(s^2 + 2 zeta wn s + wn^2)), real pole 5 Hz, resonance 40 Hz, zeta = 0.02, ZOH at "
        "1 kHz, random binary input, 10 % white output noise. Times are the best of repeated runs "
        "measured inside each tool (no process start-up, no file reading), except the whole-process "
        "row, timed from process start to exit. FRF error: relative "
        "error |G_id - G| / |G| against the true discrete plant on 400 log-spaced points from "
        "0.1 Hz to 450 Hz (0.9 Nyquist): RMS and max over the whole grid, RMS up to 100 Hz; and "
        "the peak error relative to the peak gain, max |G_id - G| / max |G|. Above ~200 Hz the "
        "plant is 60-80 dB below its DC gain and every tool's relative error there is set by the "
        "noise in its estimated D (about 2e-4 against |G| = 9e-5 at 450 Hz)."
    )
    lines.append("")
    lines.append(
        "| job | tool | time | rel. err RMS | rel. err max | rel. err RMS <= 100 Hz "
        "| peak err / peak gain |"
    )
    lines.append("|---|---|---:|---:|---:|---:|---:|")

    def n4_row(key, tool, job="N4SID n=3, i=20"):
        if key not in n4:
            lines.append("| %s | %s | not run | | | | |" % (job, tool))
            return
        t, (rms, mx, low, hinf) = n4[key][:2]
        lines.append(
            "| %s | %s | %s | %.3e | %.3e | %.3e | %.3e |"
            % (job, tool, fmt_t(t), rms, mx, low, hinf)
        )

    n4_row("ferrosid", "ferrosid")
    n4_row(
        "slicot",
        "SLICOT IB01AD/BD via Octave %s control %s"
        % (oc.get("octave_version", "?") if oc else "?", oc.get("control_version", "?") if oc else "?"),
    )
    n4_row("sippy", "SIPPY %s" % (py["sippy_version"] if py else "?"))
    if "ferrosid_auto" in n4:
        n4_row(
            "ferrosid_auto", "ferrosid", "N4SID automatic order (chose %d), i=20" % n4["ferrosid_auto"][2]
        )
    n4_row("ferrosid_no_d", "ferrosid", "N4SID n=3, i=20, D fixed to 0")
    if proc:
        lines.append(
            "| `ferrosid identify LOG --json`, whole process (read CSV, N4SID auto order, "
            "feedback test, validation, JSON; best / median of %d) | ferrosid | %s / %s | | | | |"
            % (proc["repeats"], fmt_t(proc["identify_process_best_seconds"]),
               fmt_t(proc["identify_process_median_seconds"]))
        )
    if fe:
        lines.append(
            "| Welch H1 + coherence, nperseg 1024 | ferrosid | %s | | | | |" % fmt_t(fe["welch_seconds"])
        )
    if py:
        lines.append(
            "| Welch H1 + coherence, nperseg 1024 | scipy %s (welch, welch, csd) | %s | | | | |"
            % (py["scipy_version"], fmt_t(py["scipy_welch_seconds"]))
        )
        lines.append(
            "| Welch H1 + coherence, nperseg 1024 | numpy %s one-pass (batched rfft) | %s | | | | |"
            % (py["numpy_version"], fmt_t(py["numpy_welch_seconds"]))
        )
    lines.append("")
    verdicts = []
    if "ferrosid" in n4 and "slicot" in n4:
        tf, ef = n4["ferrosid"][0], n4["ferrosid"][1]
        ts_, es = n4["slicot"][0], n4["slicot"][1]
        verdicts.append(
            "- N4SID time ferrosid / SLICOT = %.2f (target <= 0.5: %s)." % (tf / ts_, "met" if tf / ts_ <= 0.5 else "MISSED")
        )
        if proc:
            r = proc["identify_process_best_seconds"] / ts_
            verdicts.append(
                "- Whole `ferrosid identify` process / SLICOT n4sid core time = %.2f (target <= 0.5: "
                "%s)." % (r, "met" if r <= 0.5 else "MISSED")
            )
            if "identify_process_cpu_best_seconds" in proc:
                verdicts.append(
                    "- `ferrosid identify` process CPU time (user + system) best / median %s / %s; "
                    "1-minute load average %.2f when it was timed (2 cores)."
                    % (fmt_t(proc["identify_process_cpu_best_seconds"]),
                       fmt_t(proc["identify_process_cpu_median_seconds"]),
                       proc["load_average_1min"])
                )
        names = ["rel. err RMS", "rel. err max", "rel. err RMS <= 100 Hz", "peak err / peak gain"]
        parts = []
        for k, name in enumerate(names):
            ratio = ef[k] / es[k]
            parts.append(
                "%s %.3e vs %.3e (ratio %.3f, %s)"
                % (name, ef[k], es[k], ratio, "smaller or equal" if ratio <= 1.0 else "LARGER by %.1f %%" % (100 * (ratio - 1)))
            )
        verdicts.append("- FRF error ferrosid vs SLICOT: " + "; ".join(parts) + ".")
    if fe and py:
        r = fe["welch_seconds"] / py["scipy_welch_seconds"]
        verdicts.append(
            "- Welch + coherence time ferrosid / scipy = %.2f (target < 1: %s); ferrosid / "
            "one-pass numpy = %.2f." % (r, "met" if r < 1 else "MISSED", fe["welch_seconds"] / py["numpy_welch_seconds"])
        )
        # Same estimate? (sanity check of the comparison, not a timing)
        hf = np.array(fe["welch"]["h_re"]) + 1j * np.array(fe["welch"]["h_im"])
        hs = np.array(py["welch"]["h_re"]) + 1j * np.array(py["welch"]["h_im"])
        dh = np.max(np.abs(hf[1:] - hs[1:]) / np.abs(hs[1:]))
        dc = np.max(np.abs(np.array(fe["welch"]["coherence"]) - np.array(py["welch"]["coherence"])))
        verdicts.append(
            "- Same Welch estimate: max relative difference of H1 %.1e, of coherence %.1e "
            "(ferrosid vs scipy)." % (dh, dc)
        )
    lines.extend(verdicts)
    lines.append("")
    lines.append(
        "Machine: %s, %d logical CPUs (shared with other jobs while measuring); ferrosid "
        "N4SID with a second thread for half of the Hankel correlation products (faer without "
        "rayon), the whole-process row with up to two threads (CSV halves, data-only work beside "
        "N4SID); Octave/numpy with their default BLAS threads."
        % (cpu_name(), os.cpu_count() or 0)
    )
    text = "\n".join(lines) + "\n"
    with open(out, "w") as fh:
        fh.write(text)
    sys.stdout.write(text)


if __name__ == "__main__":
    main()
