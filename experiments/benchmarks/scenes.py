"""The scene the MPM and GNS benchmarks share."""

# The paper scene: the default heap of 1000 sand particles on the ramp and
# one semicircle obstacle (radius 0.04 m at x = 0.9 m), as a dict for
# ``mpm.Scene.from_dict``; each benchmark adds its ``num_frames``.
PAPER_SCENE = {"name": "paper_semicircle",
               "obstacles": [{"shape": "semicircle", "x": 0.9, "radius": 0.04}]}
