"""`dmg eval`'s summary and report (dmg_bringup.evaluation.summarise, markdown) on synthetic run records:
the executor's verdicts on its ends are counted against the truth."""
from __future__ import annotations

from dmg_bringup.evaluation import RunOutcome, markdown, summarise


def _run(name: str, outcome: str, success: bool, end_judged: str) -> RunOutcome:
    return RunOutcome(name, 0, 1.0, outcome, success, "", 2, 0.002, 1.0, 0.5, 40.0, 10.0, 10.0, 20.0, 0.0003, 0.4,
                      end_judged=end_judged)


def test_verdicts_on_the_end_are_counted_against_the_truth_per_object():
    runs = [_run("a", "OK", True, "right"), _run("a", "OUT_OF_TOLERANCE", False, "wrongly_out"),
            _run("a", "SLIP", False, ""), _run("b", "TRUTH_OUT_OF_TOLERANCE", False, "wrongly_within"),
            _run("b", "OUT_OF_TOLERANCE", False, "right")]
    summary = summarise(runs)
    assert summary["overall"]["end_judged"] == {"right": 2, "wrongly_out": 1, "wrongly_within": 1}
    assert summary["by_object"]["a"]["end_judged"] == {"right": 1, "wrongly_out": 1}
    table = markdown(summary, runs).split("| perception")[1].split("\n\n")[0].splitlines()
    rows = {line.split(" | ")[0]: line for line in table}
    assert rows["| all"].endswith("| 2/4 | 1 | 1 |")
    assert rows["| a"].endswith("| 1/2 | 1 | 0 |")
