"""The twelfth hostile pass's findings that are fixed, each run again as written (docs/notebook/hostile12.md; the
rest are in docs/notebook/boundary.md, "After the twelfth pass")."""

from __future__ import annotations

import pytest

from mjx_pusht.errors import MjxPushtError


@pytest.mark.parametrize("state", ["x", None, 5])
def test_brax_check_takes_a_state(state):
    """TRACEBACK (twelfth pass): BraxPushT().check('x') was an AttributeError ('str' object has no attribute 'info')."""
    pytest.importorskip("brax")
    from mjx_pusht.envs.brax import BraxPushT

    with pytest.raises(MjxPushtError, match="check takes the State"):
        BraxPushT(backend="mjx-jax", max_worlds=4, table=2).check(state)
