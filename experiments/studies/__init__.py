"""Every study of the project, in one shape.

A study is a module here with

* ``Settings``: a frozen dataclass (``studies.settings.Base``) holding every
  choice the study takes, each field with its default, help and bounds;
  constructing one checks it;
* ``run(settings, out_dir) -> summary``: does the work, writes its files
  into ``out_dir`` (atomically, figures through ``experiments.figures``)
  and returns a JSON-able summary;
* ``report(summary) -> str``: the summary as Markdown.

The entry point of the same name (``python -m experiments.<name>``) derives
its flags from ``Settings`` (``experiments.runtime.define_flags``) and calls
``run``: nothing else. Imports point downward: entry points -> studies ->
``gnsjax.design`` -> ``gnsjax`` -> ``mpm``.

The studies: ``evaluation`` (the paper's evaluation of a trained run),
``stability`` (where each simulator stays finite and physical),
``tradeoff`` (speed against accuracy), ``convergence`` (the MPM against its
resolution), ``design`` (where to put an obstacle, by gradients),
``design_comparison`` (gradients against derivative-free baselines),
``gradient_check`` (plain against smoothed gradients), ``calibration``
(friction from an observed deposit), ``ablation`` (the training recipe,
part by part) and ``demo`` (the end-to-end demo).
"""
