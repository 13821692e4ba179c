"""Training policies on the batch, each judged by the task's rule on held-out seeds, on MuJoCo C as on MJX.

- `policy.py`: the network, its checkpoint file, and `PolicyController` (what `--controller
  policy:PATH` runs, in NumPy on MuJoCo C and in JAX inside MJX's scan);
- `controller.py`: `policy:PATH` registered with the task's controllers;
- `dagger.py`: DAgger from the scripted expert, its rollouts (the student drives, the expert labels);
  `dagger_config.py`: its settings, teacher and seeds; `learner.py`: the fits;
- `run.py`: `train_dagger`, a DAgger run: the loop, its checkpoints, the judged curve;
- `ppo.py`: PPO with Brax's own trainer (its glue: the callbacks, stop, resume); `ppo_config.py`: its settings and
  the training reward; `ppo_judge.py`: Brax's params as a checkpoint, and the episodes that judge it;
- `resume.py`, `curve.py`, `summary.py`: what a run of either method leaves behind (the resume
  checkpoint, curve.csv/png and train.rrd, summary.json).

`mjx-pusht train` (cli/train.py) runs one and then judges the kept policy with `study.evaluate`.
Needs the `[train]` extra (flax, optax, orbax-checkpoint, brax).
"""
