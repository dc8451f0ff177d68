import itertools, numpy as np, matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from gnsjax import run as run_lib, rollout as R
from mpm import io as mpm_io
t = next(itertools.islice(mpm_io.read_trajectories("data/small1000/test.h5"), 12, None))
fig, axes = plt.subplots(2, 4, figsize=(20, 7))
for row, w in enumerate(["experiments/runs/ft_rcr_clean10_avg3", "experiments/runs/rest_cleanrest_avg5"]):
    r = run_lib.load_run(w)
    out = R.rollout_trajectory(r.model, r.params, t, r.problem)
    x = np.asarray(out.positions); idx = R.predicted_frame_indices(len(t.positions), r.problem.input_frames, r.problem.frame_stride)
    v = np.linalg.norm(np.diff(x, axis=0), axis=-1).mean(1) / (r.problem.frame_stride * t.scene.frame_dt)
    print(w, "speed cm/s at steps -1,-20,-60:", [round(100*v[i],2) for i in (-1,-20,-60)])
    for j, s in enumerate([len(x)//3, 2*len(x)//3, len(x)-30, len(x)-1]):
        ax = axes[row, j]; f = idx[s]
        ax.scatter(*t.positions[f].T, s=3, c="k", label="MPM"); ax.scatter(*x[s].T, s=3, c="r", label="GNS")
        ax.set_xlim(0, 1.65); ax.set_ylim(0, 0.8); ax.set_aspect("equal"); ax.set_title(f"{w.split('/')[-1]} frame {f}")
fig.savefig("/tmp/traj12.png", dpi=70)
