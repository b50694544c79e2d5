"""What accuracy costs in time: runs the study and writes a report (Markdown with PNG plots).

  .venv/bin/python server/bench/accuracy_report.py --out docs/accuracy          # the full study (tens of minutes)
  .venv/bin/python server/bench/accuracy_report.py --quick --out out/accuracy   # coarse, for the test suite
  .venv/bin/python server/bench/accuracy_report.py --from out/accuracy --out docs/accuracy   # re-plot only

  .venv/bin/python server/bench/accuracy_report.py --scheduler tcp://HOST:8786 --out docs/accuracy   # on a cluster

It runs, each printing its progress:
  tactile-batch accuracy              the FEM's error against references, and its cost, per element order (P1,
                                      P2), material model, mesh level, time step (fraction of the critical one)
                                      and precision; and the
                                      largest block that keeps 1 kHz real time (server/src/study/accuracy.hpp):
                                      the runs of `tactile-accuracy`, each a task on Dask (an embedded cluster
                                      of one worker per core, --workers N, or --scheduler's), into the same
                                      accuracy.json
  device-bridge/bench/bridge_bench.py modes   the bridge's rendering modes against a 1 kHz truth, soft and stiff
  build/release/fem_bench --only=effects,passes   what each effect costs, and the passes a bare step runs
and keeps their outputs (accuracy.json, modes_*.json, effects.md) beside REPORT.md, so a report can be re-plotted
from them (--from).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
from collections import defaultdict
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
MATERIALS = ["linear", "stvk", "corotational", "neohookean", "invertible_stvk"]
COLOURS = {"linear": "tab:gray", "stvk": "tab:blue", "corotational": "tab:orange", "neohookean": "tab:green",
           "invertible_stvk": "tab:purple"}
STYLE = {"double": "-", "float": "--"}
MARKER = {"double": "o", "float": "^"}
# Quadratic (P2) tets drawn apart from linear (P1) ones: squares and diamonds, dotted lines.
P2_STYLE = {"double": "-.", "float": ":"}
P2_MARKER = {"double": "s", "float": "D"}


def element(r: dict[str, Any]) -> str:
    return r.get("element", "p1")


def style(r: dict[str, Any]) -> str:
    return (P2_STYLE if element(r) == "p2" else STYLE)[r["precision"]]


def marker(r: dict[str, Any]) -> str:
    return (P2_MARKER if element(r) == "p2" else MARKER)[r["precision"]]
TITLES = {
    "cantilever_deflection": "cantilever, small tip load: deflection vs Timoshenko",
    "cantilever_frequency": "cantilever: first frequency vs Euler-Bernoulli",
    "wave_speed": "bar: wave speed vs sqrt(E/rho)",
    "fig3_tip": "paper's Fig. 3 (large sag): tip vs converged StVK",
    "fig2_area": "paper's Fig. 2 (90 deg twist): mid-section area vs converged StVK",
}


def built(name: str) -> str:
    build = pathlib.Path(os.environ.get("TACTILE_BUILD", "build/release"))
    exe = (build if build.is_absolute() else ROOT / build) / name
    if not os.access(exe, os.X_OK):
        sys.exit(f"{name} is not built (scripts/setup.sh builds it)")
    return str(exe)


# ---- running ---------------------------------------------------------------------------------------------------

def run_all(out: pathlib.Path, quick: bool, haptic_seconds: float, where: list[str]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    batch = [str(pathlib.Path(sys.executable).parent / "tactile-batch"), "accuracy",
             "--out", str(out / "accuracy.json"), "--scenes", str(ROOT / "server" / "scenes"),
             *(["--quick"] if quick else []), *where]
    print("accuracy-cost study: " + " ".join(batch[1:]), flush=True)
    subprocess.run(batch, check=True)
    if haptic_seconds > 0:
        for obj in ("soft", "stiff"):
            print(f"haptic modes, {obj} block: bridge_bench.py modes --seconds {haptic_seconds:g}", flush=True)
            subprocess.run([sys.executable, str(ROOT / "device-bridge" / "bench" / "bridge_bench.py"), "modes",
                            "--seconds", str(haptic_seconds), "--object", obj,
                            "--json", str(out / f"modes_{obj}.json")],
                           check=True)
    print("effects: fem_bench --only=effects, --only=passes", flush=True)
    tables = []
    for table in ("effects", "passes"):
        r = subprocess.run([built("fem_bench"), *(["--quick"] if quick else []), f"--only={table}"],
                           check=True, capture_output=True, text=True)
        tables.append(r.stdout.strip())
    (out / "effects.md").write_text("\n\n".join(tables) + "\n")


# ---- reading ---------------------------------------------------------------------------------------------------

def cost_per_sim_second(r: dict[str, Any]) -> float:
    """Wall seconds one core spends per simulated second: what real time asks to be under 1."""
    return r["wall_s"] / r["sim_time_s"] if r["sim_time_s"] > 0 else float("nan")


def pareto(points: list[tuple[float, float, Any]]) -> list[tuple[float, float, Any]]:
    """The points no other beats in both cost and error, cheapest first."""
    front, best = [], float("inf")
    for c, e, tag in sorted(points, key=lambda p: (p[0], p[1])):
        if e < best:
            front.append((c, e, tag))
            best = e
    return front


def label(r: dict[str, Any]) -> str:
    return (f"{element(r).upper()} {r['material']} L{r['level']} ({r['tets']} tets) {r['precision']} "
            f"dt {r['safety']:.1f}")


# ---- plots -------------------------------------------------------------------------------------------------------

def plot_convergence(records: list[dict[str, Any]], path: pathlib.Path) -> None:
    problems = [p for p in TITLES if any(r["problem"] == p for r in records)]
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    for ax, problem in zip(axes.flat, problems, strict=False):
        for el in ("p1", "p2"):
            for m in MATERIALS:
                for prec in ("double", "float"):
                    rs = sorted((r for r in records if r["problem"] == problem and r["material"] == m
                                 and element(r) == el and r["precision"] == prec and abs(r["safety"] - 0.9) < 1e-9
                                 and not r["fault"]), key=lambda r: r["nodes"] or r["tets"])
                    if rs:
                        ax.loglog([r["nodes"] or r["tets"] for r in rs], [max(abs(r["error"]), 1e-9) for r in rs],
                                  style(rs[0]), marker=marker(rs[0]), color=COLOURS[m],
                                  label=f"{el.upper()} {m} {prec}")
        ax.set_title(TITLES[problem], fontsize=10)
        ax.set_xlabel("nodes")
        ax.set_ylabel("|relative error|" if problem != "fig2_area" else "|area ratio - reference|")
        ax.grid(True, which="both", alpha=0.3)
    ax = axes.flat[len(problems)]
    rot = [r for r in records if r["problem"] in ("rotation_energy", "rotation_volume")]
    names = [f"{m} {p}" for m in MATERIALS for p in ("double", "float")]
    x = np.arange(len(names))
    for k, (problem, colour) in enumerate((("rotation_energy", "tab:red"), ("rotation_volume", "tab:purple"))):
        vals = []
        for m in MATERIALS:
            for p in ("double", "float"):
                rs = [abs(r["value"]) for r in rot
                      if r["problem"] == problem and r["material"] == m and r["precision"] == p]  # P1 and P2
                vals.append(max(max(rs), 1e-35) if rs else np.nan)
        ax.bar(x + (k - 0.5) * 0.4, vals, 0.4, color=colour,
               label="elastic energy / (E V)" if k == 0 else "|volume change| / V")
    ax.set_yscale("log")
    ax.set_xticks(x, names, fontsize=7, rotation=40, ha="right")
    ax.set_title("a body turned rigidly by 90 deg: should be 0", fontsize=10)
    ax.legend(fontsize=7)
    for a in axes.flat[len(problems) + 1:]:
        a.axis("off")
    axes.flat[0].legend(fontsize=6, ncol=2)
    fig.suptitle("Error against mesh size (nodes), per element order and material (P1: circles and triangles, "
                 "solid double, dashed float; P2: squares and diamonds, dash-dot double, dotted float; dt = 0.9 of the "
                 "critical step)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_pareto(records: list[dict[str, Any]], path: pathlib.Path) -> dict[str, list[tuple[float, float, Any]]]:
    problems = [p for p in ("cantilever_deflection", "wave_speed", "fig3_tip", "fig2_area")
                if any(r["problem"] == p for r in records)]
    fig, axes = plt.subplots(1, len(problems), figsize=(5 * len(problems), 4.6), squeeze=False)
    fronts = {}
    for ax, problem in zip(axes[0], problems, strict=True):
        rs = [r for r in records if r["problem"] == problem and not r["fault"]]
        for r in rs:
            ax.loglog(cost_per_sim_second(r), max(abs(r["error"]), 1e-9), marker(r),
                      color=COLOURS[r["material"]], alpha=0.75, ms=5)
        front = pareto([(cost_per_sim_second(r), max(abs(r["error"]), 1e-9), r) for r in rs])
        fronts[problem] = front
        ax.loglog([c for c, _, _ in front], [e for _, e, _ in front], "k-", lw=1, label="Pareto front")
        ax.axvline(1.0, color="red", lw=0.8, ls=":", label="real time")
        ax.set_title(TITLES[problem], fontsize=9)
        ax.set_xlabel("wall s per simulated s (one core)")
        ax.set_ylabel("|error|")
        ax.grid(True, which="both", alpha=0.3)
    handles = [plt.Line2D([], [], color=COLOURS[m], marker="o", ls="", label=m) for m in MATERIALS]
    handles += [plt.Line2D([], [], color="k", marker=MARKER[p], ls="", label=f"P1 {p}") for p in ("double", "float")]
    handles += [plt.Line2D([], [], color="k", marker=P2_MARKER[p], ls="", label=f"P2 {p}")
                for p in ("double", "float")]
    handles += [plt.Line2D([], [], color="k", label="Pareto front"),
                plt.Line2D([], [], color="red", ls=":", label="real time")]
    axes[0][0].legend(handles=handles, fontsize=7)
    fig.suptitle("Error against cost: every choice (element order, material, mesh, time step, precision); the front is "
                 "what to pick")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fronts


def plot_timestep(records: list[dict[str, Any]], path: pathlib.Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, problem in zip(axes, ("cantilever_frequency", "wave_speed"), strict=True):
        rs = [r for r in records if r["problem"] == problem and r["precision"] == "double" and element(r) == "p1"
              and not r["fault"]]
        if not rs:
            continue
        level = max(r["level"] for r in rs)
        for m in MATERIALS:
            pts = sorted((r for r in rs if r["material"] == m and r["level"] == level), key=lambda r: r["safety"])
            if pts:
                ax.plot([r["safety"] for r in pts], [100 * r["error"] for r in pts], marker="o", color=COLOURS[m],
                        label=m)
        ax.set_title(f"{TITLES[problem]} (P1 level {level}, double)", fontsize=9)
        ax.set_xlabel("time step / critical step")
        ax.set_ylabel("error %")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_realtime(realtime: list[dict[str, Any]], path: pathlib.Path) -> None:
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for r in realtime:
        ax.loglog(r["tets"], r["interval_ms"], style(r), marker=marker(r),
                  color=COLOURS[r["material"]], label=f"{element(r).upper()} {r['material']} {r['precision']}")
    ax.axhline(1.0, color="red", ls=":", lw=1, label="1 ms: 1 kHz real time")
    ax.set_xlabel("tets (the poke block, 8 x 4 x 8 cm, 30 kPa)")
    ax.set_ylabel("wall time of 1 ms of simulation [ms], median")
    ax.set_title("How large a body keeps 1 kHz on one core")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_haptic(rows: list[dict[str, Any]], path: pathlib.Path) -> None:
    objects = sorted({r["object"] for r in rows}, key=lambda o: ["soft", "stiff"].index(o))
    modes = ["delay", "hold", "extrapolate"]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    x = np.arange(len(modes))
    for k, obj in enumerate(objects):
        by = {r["mode"]: r for r in rows if r["object"] == obj}
        axes[0].bar(x + (k - 0.5) * 0.4, [by[m]["rms_pct"] for m in modes], 0.4, label=obj)
        axes[1].bar(x + (k - 0.5) * 0.4, [by[m]["lag_ms"] for m in modes], 0.4, label=obj)
        axes[2].bar(x + (k - 0.5) * 0.4, [by[m]["steps_mN"] / max(by[m]["truth_steps_mN"], 1e-9) for m in modes], 0.4,
                    label=obj)
    axes[0].set_ylabel("force error, rms % of the force")
    axes[1].set_ylabel("latency added (best-aligning lag) [ms]")
    axes[2].set_ylabel("buzz: tick-to-tick change / the truth's")
    axes[2].axhline(1.0, color="k", lw=0.8, ls=":")
    for ax in axes:
        ax.set_xticks(x, modes)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend()
    fig.suptitle("The bridge's rendering modes against a 1 kHz truth (server step slower than the tick)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- the report ------------------------------------------------------------------------------------------------

def pick(records: list[dict[str, Any]], **kw: Any) -> list[dict[str, Any]]:
    return [r for r in records if all(r.get(k) == v for k, v in kw.items())]


def write_report(out: pathlib.Path) -> pathlib.Path:
    data = json.loads((out / "accuracy.json").read_text())
    records, realtime = data["records"], data["realtime"]
    plot_convergence(records, out / "convergence.png")
    fronts = plot_pareto(records, out / "pareto.png")
    plot_timestep(records, out / "timestep.png")
    plot_realtime(realtime, out / "realtime.png")
    haptic = [r for obj in ("soft", "stiff") if (out / f"modes_{obj}.json").exists()
              for r in json.loads((out / f"modes_{obj}.json").read_text())]
    if haptic:
        plot_haptic(haptic, out / "haptic.png")

    L: list[str] = []
    mode = "quick (coarse levels, fewer variations)" if data.get("quick") else "full"
    L += ["# What accuracy costs in time", "",
          f"Generated by `server/bench/accuracy_report.py` ({mode}) on one core of this machine; the records are in "
          "`accuracy.json`. Errors are relative to the reference unless said otherwise; cost is wall time per step, "
          "tet-steps per second, and wall seconds per simulated second (under 1 is real time).", ""]

    # Headline findings, from the records.
    L += ["## Headline findings", ""]
    rot = {(r["material"], r["precision"]): abs(r["value"]) for r in pick(records, problem="rotation_energy")}
    if rot:
        nonlin = max(v for (m, p), v in rot.items() if m != "linear" and p == "double")
        nonlin_f = max((v for (m, p), v in rot.items() if m != "linear" and p == "float"), default=float("nan"))
        L.append(f"- **Invariance (the paper's claim).** Turned rigidly by 90 degrees, the linear model stores "
                 f"{rot.get(('linear', 'double'), float('nan')):.2f} E V of elastic energy (as if strained by ~100 %); "
                 f"StVK, corotational and Neo-Hookean store at most {nonlin:.1e} E V in double, "
                 f"{nonlin_f:.1e} in float "
                 "(round-off).")
    f2 = pick(records, problem="fig2_area", precision="double", element="p1")
    if f2:
        lvl = max(r["level"] for r in f2)
        by = {r["material"]: r for r in f2 if r["level"] == lvl}
        L.append(f"- **Fig. 2.** At level {lvl}, the twisted column's mid-section area is off the converged StVK "
                 "answer by " + ", ".join(f"{m} {100 * by[m]['error']:+.1f} %" for m in MATERIALS if m in by) +
                 ": linear strain's error is the model's and does not shrink with the mesh (corotational and "
                 "Neo-Hookean differ from StVK by their own models at these strains as well).")
    f3 = pick(records, problem="fig3_tip", precision="double", element="p1")
    if f3:
        lvl = max(r["level"] for r in f3)
        by = {r["material"]: r for r in f3 if r["level"] == lvl}
        L.append(f"- **Fig. 3.** The sagging beam's tip, linear tets, level {lvl}: " + ", ".join(
            f"{m} {100 * by[m]['error']:.1f} %" for m in MATERIALS if m in by) + " from the converged StVK tip "
            f"({by['stvk']['reference']:.3f} m, quadratic tets)." if "stvk" in by else "")
    same = defaultdict(dict)  # invertible StVK against StVK, case by case
    for r in records:
        e = r.get("error")
        if r["material"] in ("stvk", "invertible_stvk") and not r["fault"] and isinstance(e, float) and np.isfinite(e):
            same[(r["problem"], element(r), r["level"], r["precision"], r.get("safety"))][r["material"]] = e
    diffs = [abs(v["invertible_stvk"] - v["stvk"]) for v in same.values() if len(v) == 2]
    if diffs:
        within = "to the last bit" if max(diffs) == 0 else f"within {100 * max(diffs):.1g} percentage points"
        L.append(f"- **Invertible StVK** has StVK's error on every case here, {within} ({len(diffs)} cases, both "
                 "precisions): where no element is compressed past its floor the two are one function.")
    cd = pick(records, problem="cantilever_deflection", precision="double", material="stvk", element="p1")
    cd2 = sorted(pick(records, problem="cantilever_deflection", precision="double", material="stvk", element="p2"),
                 key=lambda r: r["tets"])
    if cd:
        cd.sort(key=lambda r: r["tets"])
        L.append(f"- **Mesh.** The small-load cantilever's deflection error falls from {100 * cd[0]['error']:+.1f} % "
                 f"({cd[0]['tets']} tets) to {100 * cd[-1]['error']:+.1f} % ({cd[-1]['tets']} tets): linear tets are "
                 "stiff in bending until several span the thickness" + (
                     f"; quadratic tets are {100 * cd2[0]['error']:+.1f} % off with {cd2[0]['tets']} and "
                     f"{100 * cd2[-1]['error']:+.1f} % with {cd2[-1]['tets']} (what is left is beam theory's own "
                     "difference from the 3D clamped beam)." if cd2 else "."))
    # The element order at a real-time budget: the best choice of each within one core in real time.
    for problem in ("cantilever_deflection", "fig3_tip", "fig2_area", "wave_speed"):
        best = {}
        for el in ("p1", "p2"):
            rs = [r for r in records if r["problem"] == problem and element(r) == el and not r["fault"]
                  and cost_per_sim_second(r) <= 1.0 and (problem != "fig3_tip" or r["material"] != "linear")]
            if rs:
                best[el] = min(rs, key=lambda r: abs(r["error"]))
        if len(best) == 2:
            a, b = best["p1"], best["p2"]
            ratio = abs(a["error"]) / max(abs(b["error"]), 1e-12)
            L.append(f"- **Element order, {problem}.** The best choice within one core in real time: {label(a)}, "
                     f"{abs(a['error']):.2e} off at {cost_per_sim_second(a):.3g} s/s; {label(b)}, "
                     f"{abs(b['error']):.2e} off at {cost_per_sim_second(b):.3g} s/s: P2 {ratio:.1f} times as "
                     "accurate.")
    fr = pick(records, problem="cantilever_frequency", precision="double", material="stvk")
    if fr:
        lvl = max(r["level"] for r in fr)
        errs = {r["safety"]: r["error"] for r in fr if r["level"] == lvl}
        lo, hi = min(errs), max(errs)
        L.append(f"- **Time step.** From {hi:.1f} to {lo:.1f} of the critical step the first frequency moves by "
                 f"{100 * abs(errs[hi] - errs[lo]):.3f} percentage points (level {lvl}) while the cost grows "
                 f"{hi / lo:.1f} times: below the stability limit the step buys no accuracy worth having for the "
                 "modes a hand feels; take 0.9.")
    pairs = defaultdict(dict)
    for r in records:
        if r["problem"] in ("cantilever_deflection", "fig3_tip") and not r["fault"]:
            pairs[(r["problem"], element(r), r["material"], r["level"])][r["precision"]] = r
    dd = [abs(v["float"]["error"] - v["double"]["error"]) for v in pairs.values() if len(v) == 2]
    sp = [v["double"]["us_per_step"] / v["float"]["us_per_step"] for v in pairs.values()
          if len(v) == 2 and v["float"]["us_per_step"] > 0]
    if dd:
        L.append(f"- **Precision.** Float and double differ in error by at most {100 * max(dd):.3f} percentage points "
                 f"on these problems; float steps {np.median(sp):.2f} times as fast (median).")
    rates = defaultdict(list)
    for r in records:
        if r["tets"] >= 1000 and r["tet_steps_per_s"] > 0 and not r["fault"]:
            rates[(element(r), r["material"], r["precision"])].append(r["tet_steps_per_s"])
    for el, what in (("p1", "linear tets"), ("p2", "quadratic tets")):
        if any(k[0] == el for k in rates):
            L.append(f"- **Cost per material, {what}** (median tet-steps per second, meshes of 1000 tets and more): " +
                     "; ".join(f"{m} {np.median(rates[(el, m, 'double')]) / 1e6:.1f} M (double), "
                               f"{np.median(rates[(el, m, 'float')]) / 1e6:.1f} M (float)"
                               for m in MATERIALS if (el, m, "double") in rates and (el, m, "float") in rates) + ".")
    if realtime:
        L.append("- **Real time.** The largest poke block (30 kPa, contact on) that steps 1 ms in under 1 ms on one "
                 "core: " + "; ".join(f"{element(r).upper()} {r['material']} {r['precision']} "
                                        f"{r['largest_realtime_tets']} tets "
                                        f"(~{r['estimated_max_tets']:.0f} interpolated)" for r in realtime) + ".")
    if haptic:
        for obj in ("soft", "stiff"):
            by = {r["mode"]: r for r in haptic if r["object"] == obj}
            if by:
                L.append(f"- **Haptics, {obj} block** (E = {by['delay']['E_Pa'] / 1e3:g} kPa, server step "
                         f"{by['delay']['server_dt_ms']:g} ms): " + "; ".join(
                             f"{m} {by[m]['rms_pct']:.1f} % rms error, {by[m]['lag_ms']} ms lag, buzz "
                             f"{by[m]['steps_mN'] / max(by[m]['truth_steps_mN'], 1e-9):.1f}x the truth's"
                             for m in ("delay", "hold", "extrapolate") if m in by) + ".")
    L.append("")

    # The reading: what to pick for a budget.
    L += ["## Which choice for which budget", "",
          "Each problem's Pareto front (below: no other choice is both cheaper and more accurate). The cheapest "
          "choice within each budget of wall seconds per simulated second on one core:", "",
          "| problem | budget | choice | error | cost |", "|---|---|---|---|---|"]
    for problem, front in fronts.items():
        for budget in (1.0, 10.0, 100.0):
            within = [p for p in front if p[0] <= budget]
            if within:
                c, e, r = min(within, key=lambda p: p[1])
                L.append(f"| {problem} | <= {budget:g} | {label(r)} | {e:.2e} | {c:.3g} |")
            else:
                L.append(f"| {problem} | <= {budget:g} | none fits | | |")
    L += [""]
    for problem, front in fronts.items():
        kinds = sorted({f"{element(r).upper()} {r['material']} {r['precision']}" for _, _, r in front})
        L.append(f"- {problem}: the front is made of {', '.join(kinds)}.")
    for problem in ("fig3_tip", "fig2_area"):
        rs = [r for r in records if r["problem"] == problem and not r["fault"]]
        lin = [abs(r["error"]) for r in rs if r["material"] == "linear"]
        other = [abs(r["error"]) for r in rs if r["material"] != "linear"]
        if lin and other:
            L.append(f"- {problem}: the linear model's best error is {min(lin):.2e}, the nonlinear models' "
                     f"{min(other):.2e}; no mesh takes linear strain below its model error.")
    L.append("")

    L += ["## Error against mesh size", "", "![convergence](convergence.png)", "",
          "## Error against cost", "", "![pareto](pareto.png)", "",
          "## The time step", "", "![timestep](timestep.png)", "",
          "## Real time", "", "![realtime](realtime.png)", "",
          "| element | material | precision | tets tried | ms per 1 ms | largest real-time |",
          "|---|---|---|---|---|---|"]
    for r in realtime:
        L.append(f"| {element(r).upper()} | {r['material']} | {r['precision']} | {', '.join(map(str, r['tets']))} | "
                 f"{', '.join(f'{v:.3f}' for v in r['interval_ms'])} | {r['largest_realtime_tets']} |")
    hertz = [r for r in records if r["problem"] == "hertz_radius"]
    if hertz:
        approach = {(r["element"], r["level"], round(r["load_n"], 9)): r for r in records
                    if r["problem"] == "hertz_approach"}
        by_nodes = {(r["element"], r["level"], round(r["load_n"], 9)): r for r in records
                    if r["problem"] == "hertz_radius_nodes"}
        L += ["", "## Hertz's two spheres", "",
              "`server/scenes/spheres_press.json`: two equal neo-Hookean spheres (R = 3 cm, E = 20 kPa, nu = 0.45) "
              "pressed together through their own contact, quasi-statically (density raised a hundredfold, as "
              "quasi-static explicit runs do), float. At each load (the lower sphere's base reaction, a mean over "
              "0.1 s), the contact radius and the approach of the centres, against Hertz at that load: "
              "a = (3 F R* / 4 E*)^(1/3), approach a^2 / R*, R* = R / 2, E* = E / 2 (1 - nu^2). The radius is "
              "read off the normal impulses between the spheres: their spread about their centre in the contact "
              "plane, which for Hertz's pressure p0 sqrt(1 - r^2/a^2) is a^2 / 2.5 (radius); 'nodes' is the "
              "farthest boundary node of the lower sphere within 0.05 mm of the contact plane, no finer than the "
              "nodes' spacing on the surface and lost where that plane is misplaced. Both need several of the finer "
              "surface's vertices in the patch: on level 1 the lower loads press one or two, and neither means "
              "anything there. The approach also "
              "holds the spheres' squeeze between centre and contact, which Hertz's half-spaces leave out. The cost is "
              "the mass-scaled run's: unscaled, the step is ten times shorter and the cost ten times this.", "",
              "| element | level | tets | load N | radius mm | Hertz mm | error | nodes mm | error | approach mm | "
              "Hertz mm | error | wall s per simulated s | fault |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in hertz:
            key = (r["element"], r["level"], round(r["load_n"], 9))
            a = approach.get(key)
            ap_cells = (f"{1e3 * a['value']:.3f} | {1e3 * a['reference']:.3f} | {a['error']:+.1%}" if a
                        else " | | ")
            nd = by_nodes.get(key)
            nd_cells = f"{1e3 * nd['value']:.2f} | {nd['error']:+.1%}" if nd else " | "
            L.append(f"| {element(r).upper()} | {r['level']} | {r['tets']} | {r['load_n']:.3f} | "
                     f"{1e3 * r['value']:.2f} | {1e3 * r['reference']:.2f} | {r['error']:+.1%} | {nd_cells} | "
                     f"{ap_cells} | "
                     f"{cost_per_sim_second(r):.3g} | {r['fault'][:40]} |")
    if haptic:
        L += ["", "## The haptic side", "",
              "`device-bridge/bench/bridge_bench.py modes`: the arm follows a poke open-loop; each mode's force "
              "against the force the same motion gives at 1 kHz (headless, 1 ms control interval). The trade the "
              "paper makes: the one-step delay renders a force as smooth as the truth's (buzz near 1x) at the price "
              "of a server step and the jitter allowance of latency; holding is closer on average but a staircase "
              "(buzz several times the truth's); extrapolating adds the least latency and amplifies the contact's "
              "chatter. On the stiff block the truth itself chatters (its tick-to-tick change, in brackets, is "
              "large), which dominates every mode's error there.", "",
              "The modes below drive a kinematic proxy, open-loop. The closed loop the hand feels, with the proxy "
              "coupled to the device (the default) against these direct modes, per case and at each haptic rate: "
              "[haptic_loop.md](haptic_loop.md) (`bridge_bench.py loop`).", "",
              "![haptic](haptic.png)", "",
              "| object | mode | rms N | rms % | max N | lag ms | display delay ms | buzz mN (truth) |",
              "|---|---|---|---|---|---|---|---|"]
        for r in haptic:
            L.append(f"| {r['object']} | {r['mode']} | {r['rms_N']:.3f} | {r['rms_pct']:.1f} | {r['max_N']:.3f} | "
                     f"{r['lag_ms']} | {r['delay_ms']:.2f} | {r['steps_mN']:.1f} ({r['truth_steps_mN']:.1f}) |")
    if (out / "effects.md").exists():
        L += ["", "## The effects", "",
              "`build/release/fem_bench --only=effects` and `--only=passes`. The stepper is assembled at load from "
              "the effects a scene asks for (its corrector kernel is compiled per gravity and damping; the load, "
              "essential and contact passes run only when the scene has loads, conditions or proxies), so a scene "
              "without an effect runs the code a build without it would: the bare step's passes show none of "
              "them. Differences under a few percent are this machine's noise (compare the bare step timed twice).",
              "", (out / "effects.md").read_text().strip()]
    L += ["", "## All records", "",
          "| problem | element | material | level | tets | dt | precision | value | reference | error | us/step "
          "| M tet-steps/s | fault |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        L.append(f"| {r['problem']} | {element(r).upper()} | {r['material']} | {r['level']} | {r['tets']} | "
                 f"{r['safety']:.1f} | "
                 f"{r['precision']} | {r['value']:.6g} | {r['reference']:.6g} | {r['error']:+.3e} | "
                 f"{r['us_per_step']:.1f} | {r['tet_steps_per_s'] / 1e6:.1f} | {r['fault'][:60]} |")
    path = out / "REPORT.md"
    path.write_text("\n".join(L) + "\n")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/accuracy", help="folder for REPORT.md, its plots and the raw figures")
    ap.add_argument("--quick", action="store_true", help="coarse levels and fewer variations (the test suite's)")
    ap.add_argument("--haptic-seconds", type=float, default=None,
                    help="seconds per bridge mode run (default 12, quick 0: skipped)")
    ap.add_argument("--from", dest="source", help="re-plot the figures kept in this folder instead of running")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="the study's Dask workers on this machine (default: one per core)")
    where.add_argument("--scheduler", help="run the study's runs on this Dask scheduler, tcp://HOST:8786")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    if args.source:
        src = pathlib.Path(args.source)
        out.mkdir(parents=True, exist_ok=True)
        if src.resolve() != out.resolve():
            for f in src.glob("*.json"):
                (out / f.name).write_text(f.read_text())
            if (src / "effects.md").exists():
                (out / "effects.md").write_text((src / "effects.md").read_text())
    else:
        seconds = args.haptic_seconds if args.haptic_seconds is not None else (0.0 if args.quick else 12.0)
        where = (["--workers", str(args.workers)] if args.workers else []) + \
            (["--scheduler", args.scheduler] if args.scheduler else [])
        run_all(out, args.quick, seconds, where)
    print(f"report: {write_report(out)}")


if __name__ == "__main__":
    main()
