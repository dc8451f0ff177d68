"""Tests for `experiments.figures` on synthetic trajectories (no simulation)."""

import os
import tempfile

from absl.testing import absltest
import numpy as np

import mpm
from experiments import figures
from experiments import file_jobs

SCENE = mpm.Scene.from_dict({
    "name": "pictures", "domain": {"width": 0.4, "height": 0.3},
    "ramp": {"kind": "polyline", "points": [[0.0, 0.05], [0.4, 0.15]]},
    "granular": {"box": [0.25, 0.12, 0.35, 0.2], "spacing": 0.01},
    "num_frames": 5})


class FiguresTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name
    rng = np.random.default_rng(0)
    self.x = rng.uniform([0.25, 0.15], [0.35, 0.2], (5, 30, 2))
    self.boundary = mpm.boundary_particles(SCENE)

  def test_animation_and_frame_grid_of_two_panels(self):
    panels = [("MPM", self.x), ("GNS", self.x[:, ::-1])]
    gif = figures.animate(panels, SCENE, *self.boundary,
                          os.path.join(self.dir, "a.gif"), stride=2)
    png = figures.frame_grid(panels, SCENE, *self.boundary, [0, 4],
                             os.path.join(self.dir, "f.png"))
    for path in (gif, png):
      self.assertGreater(os.path.getsize(path), 0, path)

  def test_default_frames_reach_the_deposit(self):
    self.assertEqual(file_jobs.default_frames(600), [0, 120, 240, 359, 479,
                                                      599])
    self.assertEqual(file_jobs.default_frames(3), [0, 1, 2])
    self.assertEqual(file_jobs.default_frames(1), [0])

  def test_mp4_without_ffmpeg_is_refused_not_renamed(self):
    out = os.path.join(self.dir, "a.mp4")
    with absltest.mock.patch.object(figures.shutil, "which",
                                    return_value=None):
      with self.assertRaisesRegex(mpm.InputError, "needs ffmpeg on PATH"):
        figures.animate([("MPM", self.x)], SCENE, *self.boundary, out)
    self.assertEmpty(os.listdir(self.dir))

  def test_frame_grid_draws_solids_in_metres_with_a_legend(self):
    scene = mpm.Scene.from_dict({**SCENE.to_dict(), "obstacles": [
        {"shape": "rectangle", "x": 0.15, "width": 0.03, "height": 0.03}]})
    captured = {}
    savefig = figures.plt.Figure.savefig

    def capture(fig, *args, **kwargs):
      captured["axes"] = fig.axes
      return savefig(fig, *args, **kwargs)

    with absltest.mock.patch.object(figures.plt.Figure, "savefig", capture):
      figures.frame_grid([("MPM", self.x)], scene, *mpm.boundary_particles(
          scene), [0, 4], os.path.join(self.dir, "f.png"))
    first = captured["axes"][0]
    self.assertEqual(first.get_xlabel(), "x (m)")
    self.assertIn("t = 0.00 s", first.get_title())
    labels = [t.get_text() for t in first.get_legend().get_texts()]
    self.assertEqual(labels, ["sand", "ramp", "obstacle"])
    # Ramp and obstacle filled: one filled contour set each.
    self.assertLen([c for c in first.collections
                    if type(c).__name__ in ("QuadContourSet",
                                            "PathCollection")
                    and getattr(c, "filled", False)], 2)

  def test_objective_vs_x(self):
    sweep = {"mpm": [{"x": 0.5, "smooth": 0.2}, {"x": 1.3, "smooth": 0.4}]}
    history = [{"x": 1.0, "objective": 0.3}, {"x": 0.95, "objective": 0.28}]
    path = figures.objective_vs_x(sweep, history, "passed_fraction", "mpm",
                                  os.path.join(self.dir, "o.png"))
    self.assertGreater(os.path.getsize(path), 0)

  def test_resolution_deposits_overlay_every_spacing_in_its_panel(self):
    runs = [(0.01, self.x[-1]), (0.005, self.x[-1] + 0.01)]
    path = figures.resolution_deposits(
        [("one", SCENE, runs), ("two", SCENE, runs[:1])],
        os.path.join(self.dir, "d.png"))
    self.assertGreater(os.path.getsize(path), 0)
    self.assertEqual(os.listdir(self.dir), ["d.png"])   # no temporary left


if __name__ == "__main__":
  absltest.main()
