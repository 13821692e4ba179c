"""render_mode="human": a pygame window that shows each frame, opened when the env is made.

A window that cannot be seen is refused up front, in one line: pygame missing, or no display (SDL
falls back to its "offscreen" driver, where frames would go nowhere without a word). Set
SDL_VIDEODRIVER yourself (e.g. "dummy") to run a human-mode env headless on purpose.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from mjx_pusht.errors import ConfigError

HEADLESS = ("offscreen", "dummy")
NO_DISPLAY = ("render_mode='human' needs a display, and this machine has none (DISPLAY is not set); use "
              "render_mode='rgb_array', or set SDL_VIDEODRIVER=dummy to run it headless")


def available() -> bool:
    """Whether a window can be asked for here (pygame installed; on Linux a display, or an SDL driver set)."""
    import importlib.util

    if sys.platform.startswith("linux") and not any(map(os.environ.get, ("DISPLAY", "WAYLAND_DISPLAY",
                                                                         "SDL_VIDEODRIVER"))):
        return False
    return importlib.util.find_spec("pygame") is not None


def render_modes(declared) -> list:
    """An env instance's metadata["render_modes"]: the class declares "human" (so gymnasium hands the mode to
    the env, which refuses it in one line where no window opens, rather than wrapping it in a HumanRendering
    that would draw to SDL's offscreen driver without a word); an instance lists it only where a window can open,
    so gymnasium's check_env tries the modes that work on this machine."""
    return [m for m in declared if m != "human" or available()]


class Window:
    """A `size` x `size` window showing rgb frames at `fps` (gymnasium's HumanRendering, inside the env)."""

    def __init__(self, size: int, fps: int):
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        if sys.platform.startswith("linux") and not any(map(os.environ.get, ("DISPLAY", "WAYLAND_DISPLAY",
                                                                             "SDL_VIDEODRIVER"))):
            raise ConfigError(NO_DISPLAY)  # refused before SDL, which would print its own complaint on stderr
        try:
            import pygame
        except ImportError:
            raise ConfigError("render_mode='human' needs pygame (pip install pygame); or use "
                              "render_mode='rgb_array'") from None
        try:
            pygame.display.init()
            driver = pygame.display.get_driver()
        except pygame.error as e:
            raise ConfigError(f"render_mode='human' needs a display, and none opens here ({e}); "
                              "use render_mode='rgb_array'") from None
        if driver in HEADLESS and "SDL_VIDEODRIVER" not in os.environ:
            pygame.display.quit()
            raise ConfigError(NO_DISPLAY)
        self._pygame, self.size, self.fps = pygame, size, fps
        self.screen = pygame.display.set_mode((size, size))
        self.clock = pygame.time.Clock()

    def show(self, frame: np.ndarray) -> None:
        pg = self._pygame
        pg.event.pump()
        self.screen.blit(pg.surfarray.make_surface(np.ascontiguousarray(np.swapaxes(frame, 0, 1))), (0, 0))
        pg.display.flip()
        self.clock.tick(self.fps)

    def close(self) -> None:
        if self._pygame is not None:
            self._pygame.display.quit()
        self._pygame = None
