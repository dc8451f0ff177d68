"""Every figure of the project (matplotlib lives here and nowhere else).

- ``animate`` and ``frame_grid``: trajectories as an animation and as a grid
  of frames. Each picture has one or more panels side by side (e.g. MPM and
  GNS), each a trajectory [T, N, 2] (m) of sand drawn over the scene: ramp
  and obstacles as filled solids, axes in metres, a legend.
- ``objective_vs_x``: an inverse-design study's objective against the
  obstacle's x (m), by MPM and GNS sweeps, with the optimiser's path;
  ``objective_vs_time``: the best objective so far against wall time of
  methods compared at equal budget.
- The evaluation's figures: training curves (the paper's Figs. 3-4), test
  error by checkpoint (Fig. 5), error-against-time breakdowns (Figs. 6-9),
  and the flow checks a positional MSE misses (sand inside solids or outside
  the domain, front error, the constraint's work) per step; the final
  deposits, learned over the MPM's (a front that stalls or sand left
  behind shows there).

The libraries (``mpm``, ``gnsjax``) import no matplotlib.
"""

import os
import shutil
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
# pylint: disable=g-import-not-at-top,wrong-import-position
import matplotlib.animation as animation
import matplotlib.patches as patches
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np

import mpm
from mpm import geometry
from mpm import incline

_SAND = "#1f77b4"
_RAMP = "#cccccc"
_OBSTACLE = "#d9a066"
_TYPE_COLOURS = {mpm.RAMP_TYPE: "#222222", mpm.OBSTACLE_TYPE: "#8c2d04"}


def draw_scene(ax, scene: mpm.Scene, boundary_positions=None,
               boundary_types=None):
  """The ramp and the obstacles as filled solids (from the scene's signed
  distances), axes in metres; boundary particles, where a model has them
  (positions [M, 2], types [M]), as dots on their surfaces."""
  w, h = scene.domain.width, scene.domain.height
  x, y = np.meshgrid(np.linspace(0, w, 331), np.linspace(0, h, 241))
  p = np.stack([x, y], axis=-1)
  ramp = geometry.ramp_params(scene.ramp)
  ax.contourf(x, y, np.asarray(geometry.ramp_sdf(ramp, p)), levels=[-9, 0],
              colors=[_RAMP], zorder=0)
  for o in scene.obstacles:
    phi = geometry.obstacle_sdf(ramp, geometry.obstacle_params(o), p)
    ax.contourf(x, y, np.asarray(phi), levels=[-9, 0], colors=[_OBSTACLE],
                zorder=1)
  if boundary_positions is not None:
    for t, colour in _TYPE_COLOURS.items():
      pts = boundary_positions[boundary_types == t]
      ax.scatter(pts[:, 0], pts[:, 1], s=1.5, c=colour, zorder=2,
                 linewidths=0)
  ax.set_xlim(0, w)
  ax.set_ylim(0, h)
  ax.set_aspect("equal")
  ax.set_xlabel("x (m)")
  ax.set_ylabel("y (m)")


def _legend(ax, scene: mpm.Scene):
  handles = [patches.Patch(color=_SAND, label="sand"),
             patches.Patch(color=_RAMP, label="ramp")]
  if scene.obstacles:
    handles.append(patches.Patch(color=_OBSTACLE, label="obstacle"))
  ax.legend(handles=handles, loc="upper left", fontsize=8)


def _panels(n: int, width: float = 5.0):
  fig, axes = plt.subplots(1, n, figsize=(width * n, width * 0.75),
                           squeeze=False)
  return fig, axes[0]


def animate(panels: Sequence[tuple[str, np.ndarray]], scene: mpm.Scene,
            boundary_positions: np.ndarray, boundary_types: np.ndarray,
            out: str, *, stride: int = 4, fps: int = 25) -> str:
  """Writes an animation of one or more trajectories side by side.

  Args:
    panels: (title, positions [T, N, 2]) pairs with equal T.
    out: path; ``.mp4`` needs ffmpeg on PATH, ``.gif`` only Pillow.
    stride: draw every ``stride``-th frame.

  Returns:
    The path written.
  """
  if out.endswith(".mp4") and shutil.which("ffmpeg") is None:
    raise mpm.InputError(f"{out}: an .mp4 needs ffmpeg on PATH, which this "
                         "machine lacks; allowed: a .gif, or install ffmpeg")
  fig, axes = _panels(len(panels))
  dots = []
  for ax, (title, x) in zip(axes, panels):
    draw_scene(ax, scene, boundary_positions, boundary_types)
    ax.set_title(title)
    dots.append(ax.scatter(x[0, :, 0], x[0, :, 1], s=2, c=_SAND, zorder=3,
                           linewidths=0))
  _legend(axes[0], scene)
  label = fig.suptitle("")
  frames = range(0, len(panels[0][1]), stride)

  def update(t):
    for d, (_, x) in zip(dots, panels):
      d.set_offsets(x[t])
    label.set_text(f"t = {t * scene.frame_dt:.3f} s (frame {t})")
    return dots + [label]

  anim = animation.FuncAnimation(fig, update, frames=frames, blit=False)
  writer = (animation.FFMpegWriter(fps=fps) if out.endswith(".mp4") else
            animation.PillowWriter(fps=fps))
  anim.save(out, writer=writer, dpi=80)
  plt.close(fig)
  return out


def frame_grid(panels: Sequence[tuple[str, np.ndarray]], scene: mpm.Scene,
               boundary_positions: np.ndarray, boundary_types: np.ndarray,
               frames: Sequence[int], out: str) -> str:
  """Writes a PNG grid: one row per chosen frame, one column per panel
  (the layout of the paper's Figure 2), each titled with its time (s)."""
  fig, axes = plt.subplots(len(frames), len(panels),
                           figsize=(4.5 * len(panels), 3.4 * len(frames)),
                           squeeze=False)
  for row, t in enumerate(frames):
    for col, (title, x) in enumerate(panels):
      ax = axes[row, col]
      draw_scene(ax, scene, boundary_positions, boundary_types)
      ax.scatter(x[t, :, 0], x[t, :, 1], s=2, c=_SAND, zorder=3, linewidths=0)
      ax.set_title(f"{title}, t = {t * scene.frame_dt:.2f} s (frame {t})",
                   fontsize=9)
  _legend(axes[0, 0], scene)
  fig.tight_layout()
  fig.savefig(out, dpi=80)
  plt.close(fig)
  return out


def objective_vs_x(sweep: dict[str, list[dict]], history: Sequence[dict],
                   objective: str, simulator: str, out: str,
                   smoothed: bool = False) -> str:
  """Writes a PNG of the smooth objective against the obstacle's x.

  Args:
    sweep: per simulator ("mpm", "gns"), rows with "x" (m) and "smooth"
      (``experiments.studies.design``'s sweep).
    history: the optimiser's records, with "x" and "objective".
    objective: its name (the y label).
    simulator: whose gradients the optimiser followed.
    out: the PNG's path.
    smoothed: whether they were smoothed (``method="adam_smoothed"``).

  Returns:
    The path written.
  """
  fig, ax = plt.subplots(figsize=(6, 4))
  for name, style in (("mpm", "k-o"), ("gns", "b-s")):
    if name in sweep:
      ax.plot([r["x"] for r in sweep[name]],
              [r["smooth"] for r in sweep[name]], style, ms=4,
              label=f"{name.upper()} sweep")
  ax.plot([r["x"] for r in history], [r["objective"] for r in history],
          "r.--", label=f"Adam on {'smoothed ' if smoothed else ''}"
          f"{simulator.upper()} gradients")
  ax.plot(history[0]["x"], history[0]["objective"], "r^", ms=8,
          label="start")
  ax.set_xlabel("obstacle x (m)")
  ax.set_ylabel(f"{objective} (smooth)")
  ax.legend(fontsize=8)
  _save(fig, out)
  return out


def objective_vs_time(rows: Sequence[dict], summary: dict, out: str) -> str:
  """Writes a PNG of the best MPM objective so far against wall time, one
  line per method.

  Args:
    rows: every evaluation, with "method", "seconds" (s after compilation)
      and "best" (the method's best value so far): trace.csv's rows
      (``experiments.studies.design_comparison``, ``calibration``).
    summary: with "runs" (each with "method", "evaluations"),
      "start_value", "objective", "unit", "problem" and "parameters".
    out: the PNG's path.

  Returns:
    The path written.
  """
  fig, ax = plt.subplots(figsize=(6.5, 4))
  for r in summary["runs"]:
    pts = [(q["seconds"], q["best"]) for q in rows
           if q["method"] == r["method"]]
    t, v = zip(*pts)
    ax.step(t, v, where="post", label=f"{r['method']} "
            f"({r['evaluations']} evals)")
  ax.axhline(summary["start_value"], color="gray", ls=":", label="start")
  values = [q["best"] for q in rows] + [summary["start_value"]]
  if min(values) > 0 and max(values) / min(values) > 100:
    ax.set_yscale("log")   # misfits that fall by decades
  ax.set_xlabel("wall time after compilation (s)")
  unit = f" ({summary['unit']})" if summary["unit"] else ""
  ax.set_ylabel(f"best {summary['objective']} so far, MPM{unit}")
  ax.set_title(f"{summary['problem']}: {len(summary['parameters'])} "
               "parameters", fontsize=10)
  ax.legend(fontsize=8)
  _save(fig, out)
  return out


def _save(fig, path: str):
  fig.tight_layout()
  tmp = f"{path}.tmp-{os.getpid()}.png"
  fig.savefig(tmp, dpi=100)
  plt.close(fig)
  os.replace(tmp, path)


def training_curves(log: Sequence[dict], out_dir: str):
  """fig3_training_loss.png and fig4_training_time.png from metrics.csv
  rows (step, loss, wall_time_s)."""
  steps = [int(r["step"]) for r in log]
  for name, key, label in (("fig3_training_loss", "loss", "training loss"),
                           ("fig4_training_time", "wall_time_s",
                            "training time (h)")):
    values = [float(r[key]) / (3600 if key == "wall_time_s" else 1)
              for r in log]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(steps, values)
    ax.set_xlabel("training step")
    ax.set_ylabel(label)
    if key == "loss":
      ax.set_yscale("log")
    _save(fig, os.path.join(out_dir, f"{name}.png"))


_TITLES = {"fig6_obstacles": "obstacle count", "fig7_particles":
           "particle count", "fig8_shape": "obstacle shape",
           "fig9_position": "rectangle position x (m)"}


def breakdown_curves(curves: dict[str, dict[str, np.ndarray]],
                     times: np.ndarray, out_dir: str):
  """Figs. 6-9: positional MSE against time (s) [T] per label."""
  for name, groups in curves.items():
    if not groups:
      continue
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for label, curve in groups.items():
      ax.plot(times, curve, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("positional MSE (m$^2$)")
    ax.set_yscale("log")
    ax.set_title(_TITLES.get(name, name))
    ax.legend()
    _save(fig, os.path.join(out_dir, f"{name}.png"))


def checkpoint_errors(errors: dict[int, float], path: str):
  """Fig. 5: test MSE (m^2) of each checkpoint step."""
  fig, ax = plt.subplots(figsize=(5, 3.5))
  ax.plot(list(errors), list(errors.values()), "o-")
  ax.set_xlabel("training step")
  ax.set_ylabel("test positional MSE (m$^2$)")
  ax.set_yscale("log")
  _save(fig, path)


def flow_checks(results: Sequence[dict], frame_dt: float, path: str):
  """Per step, mean over trajectories of each test group: sand inside solids
  (with and without the constraint), outside the domain, the front error
  and the fraction the constraint pushed. ``results`` from
  ``experiments.studies.evaluation.rollout_split``."""
  groups: dict[str, list] = {}
  for r in results:
    groups.setdefault(r["group"], []).append(r)
  panels = [("inside_solids", "sand inside solids (constrained)", 100),
            ("free_inside_solids", "sand inside solids (no constraint)", 100),
            ("outside_domain", "sand outside the domain (constrained)", 100),
            ("runout_error", "front error (m)", 1),
            ("pushed_fraction", "sand pushed out per step", 100),
            ("mse", "positional MSE (m$^2$)", 1)]
  fig, axes = plt.subplots(2, 3, figsize=(14, 7))
  for ax, (key, title, scale) in zip(axes.flat, panels):
    for name, members in sorted(groups.items()):
      if key not in members[0]:
        continue
      curve = np.mean([m[key] for m in members], 0) * scale
      ax.plot(members[0]["frames"] * frame_dt, curve, label=name)
    ax.set_title(title)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("% of the sand" if scale == 100 else "")
    if key == "mse":
      ax.set_yscale("log")
  axes.flat[0].legend(fontsize=7)
  _save(fig, path)


def final_deposits(results: Sequence[dict], path: str,
                   columns: int = 4) -> str:
  """The last frame of the learned rollout over the MPM's, for the first
  test trajectory of each group: one panel each, the whole domain, so that
  sand that stops short, runs on or stays behind is seen.

  Args:
    results: ``experiments.studies.evaluation.rollout_split``'s, each with
      its ``trajectory`` (scene), ``truth`` and ``predicted`` [T, N, 2] (m).
    path: the PNG to write.

  Returns:
    ``path``.
  """
  firsts = {}
  for r in results:
    firsts.setdefault(r["group"], r)
  cases = [firsts[g] for g in sorted(firsts)]
  columns = min(columns, len(cases))
  rows = -(-len(cases) // columns)
  fig, axes = plt.subplots(rows, columns, figsize=(4.5 * columns, 3.4 * rows),
                           squeeze=False)
  for ax, r in zip(axes.ravel(), cases):
    draw_scene(ax, r["trajectory"].scene)
    for label, x, colour in (("MPM", r["truth"][-1], "#222222"),
                             ("GNS", r["predicted"][-1], "#d62728")):
      ax.scatter(x[:, 0], x[:, 1], s=3, color=colour, alpha=0.7,
                 linewidths=0, label=label, zorder=3)
    ax.set_title(f"{r['group']} ({r['name']})", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", markerscale=3)
  for ax in axes.ravel()[len(cases):]:
    ax.axis("off")
  _save(fig, path)
  return path


def resolution_deposits(
    cases: Sequence[tuple[str, mpm.Scene, Sequence[tuple[float, np.ndarray]]]],
    path: str, columns: int = 4) -> str:
  """Final deposits of one scene at several particle spacings, overlaid.

  Args:
    cases: (title, scene, [(spacing (m), final positions [N, 2] (m)), ...]),
      one panel each, zoomed to the sand; coarse to fine.
    path: the PNG to write.

  Returns:
    ``path``.
  """
  columns = min(columns, len(cases))
  rows = -(-len(cases) // columns)
  fig, axes = plt.subplots(rows, columns, figsize=(4.5 * columns, 3.2 * rows),
                           squeeze=False)
  colours = plt.get_cmap("viridis")
  for ax, (title, scene, runs) in zip(axes.ravel(), cases):
    draw_scene(ax, scene)
    everything = np.concatenate([x for _, x in runs])
    finest = min(spacing for spacing, _ in runs)
    for k, (spacing, x) in enumerate(runs):
      ax.scatter(x[:, 0], x[:, 1], s=min(30.0, 2.0 * (spacing / finest)**2),
                 color=colours(k / max(len(runs) - 1, 1)), alpha=0.6,
                 linewidths=0, label=f"{spacing * 1000:g} mm", zorder=3)
    low, high = everything.min(0), everything.max(0)
    pad = 0.08 * max(high[0] - low[0], high[1] - low[1], 0.05)
    ax.set_xlim(low[0] - pad, high[0] + pad)
    ax.set_ylim(max(0.0, low[1] - pad), high[1] + pad)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="best")
  for ax in axes.ravel()[len(cases):]:
    ax.axis("off")
  _save(fig, path)
  return path


def pareto(summary: Sequence[dict], path: str, batched: bool = False):
  """Error against cost (log-log): each configuration's worst front error
  over the study's scenes (filled) and median (hollow) against its seconds
  per trajectory, the Pareto front joined. ``summary`` from
  ``experiments.studies.tradeoff.summarise``; the reference (zero error) is
  left out.
  """
  key = "seconds_batched" if batched else "seconds"
  fig, ax = plt.subplots(figsize=(6.5, 4.5))
  shown = sorted((e for e in summary if e[key] and e["front_error_max"] > 0
                  and np.isfinite(e["front_error_max"])),
                 key=lambda e: e[key])
  for i, e in enumerate(shown):
    color = "k" if e["kind"] == "mpm" else "tab:blue"
    marker = "o" if e["kind"] == "mpm" else "s"
    ax.plot(e[key], e["front_error_max"], marker, color=color, ms=7)
    ax.plot(e[key], max(e["front_error_median"], 1e-4), marker, color=color,
            mfc="none", ms=7)
    label = (f"MPM {e['spacing'] * 1000:g} mm" if e["kind"] == "mpm"
             else f"GNS {e['name']}")
    # Neighbours in cost alternate above and below, so labels do not touch.
    ax.annotate(label, (e[key], e["front_error_max"]), fontsize=7,
                xytext=(4, 5 if i % 2 == 0 else -10),
                textcoords="offset points")
  front = sorted((e[key], e["front_error_max"]) for e in shown if e["pareto"])
  if front:
    ax.plot(*zip(*front), "r--", lw=1, label="Pareto front (worst scene)")
  kinds = {e["kind"] for e in shown}
  if "mpm" in kinds:
    ax.plot([], [], "ko", label="MPM (worst / median scene)")
  if "gns" in kinds:
    ax.plot([], [], "s", color="tab:blue", label="GNS (worst / median scene)")
  ax.set_xscale("log")
  ax.set_yscale("log")
  for axis in (ax.xaxis, ax.yaxis):   # plain numbers at 1, 2, 5 x 10^k
    axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1, 2, 5)))
    axis.set_major_formatter(
        matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
  ax.set_xlabel("seconds per trajectory" + (" (batched)" if batched else ""))
  ax.set_ylabel("front error (fraction of the runout)")
  ax.legend(fontsize=7)
  _save(fig, path)


def column_validation(rows: Sequence[dict], deposits: dict, path: str,
                      slope: float, band: float, exponent: float,
                      height_exponent: float) -> str:
  """Column collapses against the laboratory (``experiments.validation``):
  the runout against aspect ratio per rheology, with the linear law
  (``slope`` a +- ``band``, a <= 1) and a^``exponent`` through the measured
  a = 2 point; h0 / h likewise with a^``height_exponent``; and the final
  deposits' surfaces, ``deposits[rheology]`` = [(aspect ratio, x / L0,
  height / L0)], a colour per aspect ratio, a line style per rheology."""
  rheologies = list(dict.fromkeys(r["rheology"] for r in rows))
  fig, axes = plt.subplots(1, 3, figsize=(15.0, 4.2))
  a = np.geomspace(0.3, 1.0, 20)
  axes[0].fill_between(a, slope * a * (1 - band), slope * a * (1 + band),
                       color="#dddddd", label=f"{slope:g} a +- {band:.0%}")
  for ax, key, power in ((axes[0], "runout", exponent),
                         (axes[1], "h0_over_h", height_exponent)):
    for k, rheology in enumerate(rheologies):
      mine = [r for r in rows if r["rheology"] == rheology]
      aspects = np.array([r["aspect_ratio"] for r in mine])
      values = np.array([r[key] for r in mine])
      ax.plot(aspects, values, "o-", color=f"C{k}", label=rheology)
      tall = aspects >= 2
      if tall.any():
        a0, v0 = aspects[tall][0], values[tall][0]
        at = np.geomspace(a0, aspects.max(), 20)
        ax.plot(at, v0 * (at / a0)**power, ":", color=f"C{k}",
                label=f"a^{power:.2g} through a = {a0:g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("aspect ratio a = h0 / L0")
    ax.legend(fontsize=7)
  axes[0].set_ylabel("runout (L - L0) / L0")
  axes[1].set_ylabel("h0 / h (initial over final height)")
  ax = axes[2]
  styles = ("-", "--", ":", "-.")
  aspects = sorted({r["aspect_ratio"] for r in rows})
  colours = plt.get_cmap("viridis")
  for j, rheology in enumerate(rheologies):
    for aspect, x, height in deposits.get(rheology, []):
      k = aspects.index(aspect)
      ax.plot(x, height, styles[j % len(styles)],
              color=colours(k / max(len(aspects) - 1, 1)),
              label=f"a = {aspect:g}, {rheology}")
  ax.set_xlabel("x / L0")
  ax.set_ylabel("deposit surface / L0")
  ax.set_title("final deposits", fontsize=9)
  ax.legend(fontsize=6, ncol=2)
  _save(fig, path)
  return path


def incline_profiles(profiles: dict, path: str) -> str:
  """Steady flow down the incline (``experiments.validation``): for each
  (rheology, angle), the final velocity profile u(z) against the Bagnold
  profile (mu(I) only), and the surface speed over time."""
  fig, (ax_u, ax_t) = plt.subplots(1, 2, figsize=(10.0, 4.0))
  for k, ((rheology, angle), (z, u, strip, times, speeds)) in enumerate(
      profiles.items()):
    colour = f"C{k}"
    label = f"{rheology}, {angle:g} deg"
    ax_u.scatter(u, z * 1e3, s=1, color=colour, alpha=0.4)
    m = strip.setup.scene.material
    if rheology == "mu_i":
      zz = np.linspace(0, strip.depth, 100)
      ax_u.plot(incline.bagnold_velocity(zz, strip.depth, strip.theta, m),
                zz * 1e3, "-", color=colour, label=f"Bagnold, {angle:g} deg")
    ax_t.plot(times, speeds, "-", color=colour, label=label)
  ax_u.set_xlabel("downslope velocity u (m/s)")
  ax_u.set_ylabel("height above the base z (mm)")
  ax_u.set_title("profile at the end (dots: MPM particles)", fontsize=9)
  ax_u.legend(fontsize=7)
  ax_t.set_xlabel("time (s)")
  ax_t.set_ylabel("surface speed (m/s)")
  ax_t.set_yscale("log")
  ax_t.legend(fontsize=7)
  _save(fig, path)
  return path
