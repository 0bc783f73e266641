"""The plots of ``pdr run --plot`` (matplotlib, Agg backend): ``trajectory.png`` (the path, its 1-sigma uncertainty
ellipses, GNSS fixes used and dropped) and ``bouts.png`` (walking bouts: speed, cadence, lift and power per step)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pdr.io.atomic import atomic_path

MAX_ELLIPSES = 60  # ellipses drawn at evenly spaced poses; more would hide the path
SIGMA_SCALE = 1.0


def write_plot(path: Path, traj: pd.DataFrame, *, gnss: pd.DataFrame | None = None, title: str = "") -> None:
    """Draw the trajectory in the local east/north frame.

    Parameters
    ----------
    traj : ``t_s, e_m, n_m, heading_rad, e_std_m, n_std_m``.
    gnss : optional ``t_s, e_m, n_m, used`` (bool) and optional ``masked`` (bool): fixes the run used (green dots), those
        it dropped (red crosses: rejected as outliers or not fused) and those masked by the configuration (grey pluses).
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.patches import Ellipse

    fig = Figure(figsize=(7.0, 7.0), dpi=110)
    ax = fig.subplots()
    e, n = traj["e_m"].to_numpy(), traj["n_m"].to_numpy()
    e_std, n_std = traj["e_std_m"].to_numpy(), traj["n_std_m"].to_numpy()
    # the view: the path and the GNSS fixes (not the ellipses: a weak start prior may be kilometres wide)
    xs, ys = [e], [n]
    if gnss is not None and len(gnss):
        xs.append(gnss["e_m"].to_numpy(float))
        ys.append(gnss["n_m"].to_numpy(float))
    x_all, y_all = np.concatenate(xs), np.concatenate(ys)
    ok_xy = np.isfinite(x_all) & np.isfinite(y_all)
    if ok_xy.any():
        x_all, y_all = x_all[ok_xy], y_all[ok_xy]
        span = max(float(np.ptp(x_all)), float(np.ptp(y_all)), 1.0)
        half = 0.58 * span  # a square view (equal axes) with a margin of 8% of the span
        cx, cy = 0.5 * (float(x_all.min()) + float(x_all.max())), 0.5 * (float(y_all.min()) + float(y_all.max()))
        xlim, ylim = (cx - half, cx + half), (cy - half, cy + half)
    else:
        span, xlim, ylim = 1.0, (-1.0, 1.0), (-1.0, 1.0)
    idx = np.unique(np.linspace(0, len(traj) - 1, min(len(traj), MAX_ELLIPSES)).round().astype(int)) if len(traj) else []
    drawn, too_wide = [], 0
    for i in idx:
        if not (np.isfinite(e_std[i]) and np.isfinite(n_std[i]) and (e_std[i] > 0 or n_std[i] > 0)):
            continue
        if SIGMA_SCALE * max(e_std[i], n_std[i]) > span:
            too_wide += 1
            continue
        drawn.append(i)
    label = "1-sigma uncertainty" + (f" ({too_wide} wider than the view not drawn)" if too_wide else "")
    for k, i in enumerate(drawn):
        ax.add_patch(Ellipse((e[i], n[i]), 2 * SIGMA_SCALE * e_std[i], 2 * SIGMA_SCALE * n_std[i], facecolor="tab:blue",
                             alpha=0.12, edgecolor="none", label=label if k == 0 else None))
    if gnss is not None and len(gnss):
        ok = np.isfinite(gnss["e_m"].to_numpy()) & np.isfinite(gnss["n_m"].to_numpy())
        masked = gnss["masked"].to_numpy(bool) & ok if "masked" in gnss.columns else np.zeros(len(gnss), bool)
        used = gnss["used"].to_numpy(bool) & ok
        dropped = ~gnss["used"].to_numpy(bool) & ok & ~masked
        ax.plot(gnss["e_m"][used], gnss["n_m"][used], "o", ms=3, color="tab:green", label=f"GNSS used ({used.sum()})")
        ax.plot(gnss["e_m"][dropped], gnss["n_m"][dropped], "x", ms=4, color="tab:red", label=f"GNSS dropped ({dropped.sum()})")
        if masked.any():
            ax.plot(gnss["e_m"][masked], gnss["n_m"][masked], "+", ms=4, color="tab:gray", label=f"GNSS masked ({masked.sum()})")
    ax.plot(e, n, "-", lw=1.2, color="tab:blue", label="trajectory")
    if len(traj):
        ax.plot(e[:1], n[:1], "^", color="black", label="start")
        ax.plot(e[-1:], n[-1:], "s", color="black", label="end")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, lw=0.3)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="best", fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})


def write_bouts_plot(path: Path, bouts: pd.DataFrame, steps: pd.DataFrame, *, title: str = "") -> None:
    """``bouts.png``: per step over time, the speed and cadence (top), the trunk's lift (middle) and the powers against
    gravity and inertia and the external power (bottom); the bouts shaded and numbered.

    ``bouts``: ``bouts.csv``; ``steps``: the per-step mechanics (:data:`pdr.gait.mechanics.STEP_COLUMNS`).
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 7.5), dpi=110)
    ax_speed, ax_lift, ax_power = fig.subplots(3, 1, sharex=True)
    t_mid = 0.5 * (steps["t_start_s"].to_numpy(float) + steps["t_end_s"].to_numpy(float))
    dur = (steps["t_end_s"] - steps["t_start_s"]).to_numpy(float)
    for ax in (ax_speed, ax_lift, ax_power):
        for b in bouts.itertuples():
            ax.axvspan(b.t_start_s, b.t_end_s, color="tab:gray", alpha=0.12, lw=0)
        ax.grid(True, lw=0.3)
    for b in bouts.itertuples():
        ax_speed.annotate(str(b.bout_id), (0.5 * (b.t_start_s + b.t_end_s), 1.0), xycoords=("data", "axes fraction"),
                          ha="center", va="bottom", fontsize=7)
    ax_speed.plot(t_mid, steps["speed_mps"], ".", ms=3, color="tab:blue", label="speed")
    ax_speed.set_ylabel("speed (m/s)", color="tab:blue")
    ax_cad = ax_speed.twinx()
    ax_cad.plot(t_mid, 60.0 / np.where(dur > 0, dur, np.nan), ".", ms=3, color="tab:orange", label="cadence")
    ax_cad.set_ylabel("cadence (steps/min)", color="tab:orange")
    ax_lift.plot(t_mid, 1e3 * steps["lift_m"].to_numpy(float), ".", ms=3, color="tab:green")
    ax_lift.set_ylabel("trunk lift (mm)")
    for kind, color in (("gravity", "tab:red"), ("inertia", "tab:purple"), ("external", "black")):
        ax_power.plot(t_mid, steps[f"work_{kind}_j"].to_numpy(float) / np.where(dur > 0, dur, np.nan), ".", ms=3,
                      color=color, label=f"against {kind}" if kind != "external" else "external (total)")
    ax_power.set_ylabel("power (W)")
    ax_power.set_xlabel("time (s)")
    if steps[["work_gravity_j", "work_inertia_j"]].notna().any().any():
        ax_power.legend(loc="best", fontsize=7)
    else:
        ax_power.text(0.5, 0.5, "no mechanics (no trunk sensor, precise GNSS or body mass)", transform=ax_power.transAxes,
                      ha="center", va="center", fontsize=8)
    fig.suptitle(title, fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
