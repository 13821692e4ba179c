"""What the functional env's episodes show: obs["state"], obs["keypoints"], a random goal's pose, gym-pusht's
pusher velocity, and obs["pixels"] (rendered inside the jitted step on MJX, by MuJoCo C's renderer on cpu).
"""

from __future__ import annotations

from mjx_pusht.api import keyword_checked
from mjx_pusht.envs.state import State
from mjx_pusht.task.rules import observe


@keyword_checked  # every public method: an unknown keyword is one line naming the known ones
class Observes:
    """PushTEnv's observations (a mixin: the env's fields and backend are PushTEnv's)."""

    @property
    def renderer(self):
        """cpu: the renderer of obs["pixels"], made on first use (no GL context before then, so an env made in a
        parent process can be forked) and again after `close`."""
        if self._cpu_renderer is None:
            from mjx_pusht.render.pixels import CpuRenderer

            self._cpu_renderer = CpuRenderer(self.model, self.pixels)
        return self._cpu_renderer

    def close(self) -> None:
        """Free this env's GL context (cpu pixels); the next image makes a new one."""
        r, self._cpu_renderer = getattr(self, "_cpu_renderer", None), None
        if r is not None:
            r.close()

    def with_pixels(self, state: State) -> State:
        """`state` with this world's image in obs["pixels"] (under vmap over the batch; a no-op without pixels).
        Wrappers render once, after they have replaced the rows that ended."""
        if not self.pixels:
            return state
        return state._replace(obs={**state.obs, "pixels": self._renderer(state.data, state.carry.get("goal"))})

    def images(self, n: int):
        """A jittable function: (n, 5) observation states (pusher x, y, tee x, y, yaw) -> the (n, size, size, 3)
        uint8 images `obs["pixels"]` shows of them (a learner renders its minibatches again from the states, rather
        than keeping their images: train/dagger.py). On MJX by the raster renderer, whichever draws obs["pixels"]
        (MJX-Warp's bytes on every state tested, and plain JAX ops: a data-parallel fit runs it on every device);
        on cpu by MuJoCo C's renderer, as obs["pixels"]."""
        if self.backend != "cpu":
            from mjx_pusht.render.raster import state_images

            return state_images(self)
        from mjx_pusht.render.pixels import state_images

        return state_images(self, n)

    def _observe(self, qpos, data, pixels=True, qvel=None, goal=None):
        # a random goal's pose beside the T's (a fixed goal is the origin, never observed)
        obs = observe(self.layout.pusher_xy(qpos), self.layout.tee_pose(qpos), self.keypoints) | (
            {} if goal is None else {"goal": goal})
        if self.scene.variant == "gym-pusht":  # gym-pusht reports its agent's velocity (info["vel_agent"])
            if qvel is None:
                qvel = data.qvel[-1] if self.backend == "cpu" else data.qvel
            # the pusher's slide joints: in this scene (no free joint) dof addresses are qpos addresses
            obs["pusher_vel"] = qvel[..., list(self.layout.pusher)]
        if self.pixels and pixels:
            if self.backend == "cpu":  # the target drawn at each episode's goal (None: the scene's)
                obs["pixels"] = self.renderer(qpos, goal)
            else:  # under vmap: this world's image, from the renderer made for this batch size
                obs["pixels"] = self._renderer(data, goal)
        return obs
