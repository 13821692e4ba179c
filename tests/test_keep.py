"""--keep best chooses among fits by a validation rollout the student drove alone (the expert's share negligible),
so a fit helped by the expert's last corrections is not kept over a better student."""

from __future__ import annotations

import json
from pathlib import Path

from mjx_pusht.train.curve import VALIDATION_BETA, kept

RUN = Path(__file__).resolve().parents[1] / "outputs" / "reports" / "train" / "dagger-pixels-gym-pusht-h200-17min"


def row(i, beta, validation, held_out):
    return {"iteration": i, "validation_beta": beta, "validation_success": validation, "success": held_out}


def test_a_validation_the_expert_still_helped_is_not_compared_with_the_students_own():
    curve = [row(12, 0.0097, 0.973, 0.923), row(40, 6e-7, 0.962, 0.955), row(58, 1e-9, 0.968, 0.963)]
    assert kept(curve, "best")["iteration"] == 58
    assert kept(curve, "last")["iteration"] == 58
    assert kept(curve[:1], "best")["iteration"] == 12  # none validated: the last fit


def test_on_a_real_run_the_kept_fit_is_near_the_students_best_held_out_judgement():
    """Seed 0 of the committed pixel runs (one H200, trained with the old share, 0.01): its curve's fits as judged on
    held-out seeds; the rule must now keep a fit within 1.5 points of the best judgement after the expert left."""
    curve = json.loads((RUN / "seed-0" / "summary.json").read_text())["curve"]
    late = [r for r in curve if r["validation_beta"] is not None and r["validation_beta"] <= VALIDATION_BETA]
    assert late and kept(curve, "best")["success"] >= max(r["success"] for r in late) - 0.015
