"""The target T, drawn only: the one MJCF fragment the chapter's scene and its variants both format."""

from __future__ import annotations

TARGET_TEMPLATE = """
    <body name="target" pos="0 0 0.0005">
      <site name="target_site" pos="0 0 0" size="0.005" rgba="0 0 0 0"/>
      <geom name="target_bar" type="box" size="{bx} {by} 0.0005" pos="0 0.00 0" rgba="{rgba}" contype="0" conaffinity="0"/>
      <geom name="target_stem" type="box" size="{sx} {sy} 0.0005" pos="0 -0.06 0" rgba="{rgba}" contype="0" conaffinity="0"/>
    </body>"""


def target_mjcf(rgba: str, grow: float = 0.0) -> str:
    """The target T in `rgba`; `grow` widens the drawing by that many metres a side (the gym-pusht
    variant's pygame fill)."""
    return TARGET_TEMPLATE.format(bx=round(0.06 + grow, 6), by=round(0.015 + grow, 6), sx=round(0.015 + grow, 6),
                                  sy=round(0.045 + grow, 6), rgba=rgba)
