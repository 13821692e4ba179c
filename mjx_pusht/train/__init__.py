"""Training policies on the batch, verified on MuJoCo C (issue 22).

- `policy.py`: the network, its checkpoint file, and `PolicyController` (what `--controller
  policy:PATH` runs, in NumPy on MuJoCo C and in JAX inside MJX's scan);
- `dagger.py`: DAgger from the scripted expert;
- `run.py`: `mjx-pusht train`: the loop, checkpoints and --resume, the curve, the summary.

Needs the `[train]` extra (flax, optax, orbax-checkpoint, brax).
"""
