"""secure.paper_reference and secure.report_hints: what tools/report asks of a domain through the
registry (secure/experiments/report_hints.h)."""
import pytest

import secure


def test_paper_reference_gives_each_domains_numbers():
    derby = secure.paper_reference("derby")["table3"]
    rows = {r["method"]: r for r in derby["rows"]}
    assert rows["secure"]["dangerous"] == 4.2 and rows["airl"]["success_std"] == 4.7
    assert "Demolition Derby" in derby["source"] and "Mann-Whitney" in derby["comparison"]
    kitchen = secure.paper_reference("kitchen-cutting")["table3"]
    assert kitchen["rows"][2]["success_std"] is None  # the paper gives no std: null, not NaN
    gt = secure.paper_reference("double-integrator")
    assert "table3" not in gt and gt["ground_truth_study"]["under_conservative"] == 4.1
    assert secure.paper_reference("coffee-placing")["user_study"]["rows"]


def test_report_hints_follow_the_domains_options():
    default = secure.report_hints("double-integrator")
    assert default["barrier"]["x"]["feature"] == "x"
    assert default["barrier"]["shapes"][0]["center"] == [5.0, 5.0]
    moved = secure.report_hints("double-integrator", task={"obstacle": [4.0, 6.0], "radius": 1.5})
    assert moved["barrier"]["shapes"][0]["center"] == [4.0, 6.0]
    assert moved["trajectories"]["shapes"][0]["radius"] == 1.5
    assert secure.report_hints("panda-push")["trajectories"] is None


def test_a_domain_without_hints_and_an_unknown_domain():
    assert secure.report_hints("kitchen-cutting") is None
    with pytest.raises(ValueError, match="no-such-domain"):
        secure.report_hints("no-such-domain")
    with pytest.raises(ValueError, match="no-such-domain"):
        secure.paper_reference("no-such-domain")
