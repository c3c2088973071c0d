"""The report on fixed CSVs: its statistics against values computed by hand, its claims, its files."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from services.experiments.claims import check_claims
from services.experiments.report import build_report
from services.experiments.results import load_results
from services.experiments.stats import holm
from tests.experiments.helpers import row, write_trials

# ARROCH and one baseline at one team size. By hand:
#   a = 600 610 620 630: mean 615, squared deviations 225+25+25+225 = 500, variance 500/3
#   b = 620 640 660 680: mean 650, squared deviations 900+100+100+900 = 2000, variance 2000/3
A = [600.0, 610.0, 620.0, 630.0]
B = [620.0, 640.0, 660.0, 680.0]
SE2 = (500 / 3) / 4 + (2000 / 3) / 4  # 208.333...
WELCH_T = -35 / math.sqrt(SE2)  # -2.4248711
WELCH_DF = SE2**2 / (((500 / 3) / 4) ** 2 / 3 + ((2000 / 3) / 4) ** 2 / 3)  # 75/17 = 4.4117647
COHEN_D = -35 / math.sqrt((500 + 2000) / 6)  # pooled variance (3·500/3 + 3·2000/3) / 6
# U of a: pairs with a > b: (630, 620) = 1; ties: (620, 620) = 0.5.
MWU_U = 1.5
RANK_BISERIAL = 2 * 1.5 / 16 - 1  # -0.8125
# Normal approximation with the tie and continuity corrections: mean n1 n2 / 2 = 8; one tie of size 2.
MWU_Z = (abs(MWU_U - 8) - 0.5) / math.sqrt(16 / 12 * ((8 + 1) - (2**3 - 2) / (8 * 7)))
MWU_P = math.erfc(MWU_Z / math.sqrt(2))  # two-sided: 0.081429
T_975_3 = 3.182446305284263  # Student t, 97.5 % quantile, 3 degrees of freedom (tables)
CI_HALF = T_975_3 * math.sqrt(500 / 3) / math.sqrt(4)


def welch_p_by_integration(t: float, df: float) -> float:
    """Two-sided p of Student's t with ``df`` degrees of freedom, from the regularized incomplete beta
    I_x(df/2, 1/2) at x = df/(df + t²), integrated with Simpson's rule (independent of scipy)."""
    a, b = df / 2, 0.5
    x = df / (df + t * t)
    n = 20000
    h = x / n
    log_beta = math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)

    def f(u: float) -> float:
        return 0.0 if u == 0.0 else math.exp((a - 1) * math.log(u) + (b - 1) * math.log(1 - u) - log_beta)

    total = f(0.0) + f(x) + sum((4 if i % 2 else 2) * f(i * h) for i in range(1, n))
    return total * h / 3


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture
def fixed(tmp_path: Path) -> Path:
    rows = [row("arroch", 2, i, team=v, doors=d) for i, (v, d) in enumerate(zip(A, [1, 2, 2, 3]))]
    rows += [row("no-comm", 2, i, team=v, doors=d) for i, (v, d) in enumerate(zip(B, [5, 6, 6, 7]))]
    rows.append(row("no-comm", 2, 4, team=None, doors=None, status="timeout", reason="no end of mission within 900 s wall"))
    write_trials(tmp_path, rows)
    return tmp_path


def test_summary_and_tests_match_hand_computed_values(fixed: Path) -> None:
    build_report(fixed)
    summary = {r["method"]: r for r in _csv(fixed / "summary.csv")}
    arroch = summary["arroch"]
    assert float(arroch["team_completion_time_mean"]) == pytest.approx(615.0)
    assert float(arroch["team_completion_time_ci_low"]) == pytest.approx(615.0 - CI_HALF, abs=1e-3)
    assert float(arroch["team_completion_time_ci_high"]) == pytest.approx(615.0 + CI_HALF, abs=1e-3)
    assert float(arroch["door_openings_mean"]) == pytest.approx(2.0)
    # The timed-out trial is counted but kept out of the statistics.
    assert summary["no-comm"]["trials"] == "5" and summary["no-comm"]["timeout"] == "1"
    assert summary["no-comm"]["team_completion_time_n"] == "4"

    tests = {(r["metric"], r["baseline"]): r for r in _csv(fixed / "tests.csv")}
    team = tests[("team_completion_time", "no-comm")]
    assert float(team["difference"]) == pytest.approx(-35.0)
    assert float(team["welch_t"]) == pytest.approx(WELCH_T, abs=1e-3)
    assert float(team["welch_df"]) == pytest.approx(WELCH_DF, abs=1e-2)
    assert float(team["welch_p"]) == pytest.approx(welch_p_by_integration(WELCH_T, WELCH_DF), abs=1e-5)
    assert float(team["mwu_u"]) == pytest.approx(MWU_U)
    assert float(team["mwu_p"]) == pytest.approx(MWU_P, abs=1e-5)
    assert float(team["cohen_d"]) == pytest.approx(COHEN_D, abs=1e-3)
    assert float(team["rank_biserial"]) == pytest.approx(RANK_BISERIAL)
    # Door openings: a = 1 2 2 3, b = 5 6 6 7: every pair favours ARROCH.
    doors = tests[("door_openings", "no-comm")]
    assert float(doors["difference"]) == pytest.approx(-4.0)
    assert float(doors["rank_biserial"]) == pytest.approx(-1.0)
    assert float(doors["mwu_u"]) == 0.0
    # Two tests per metric family (one level, one baseline): Holm leaves a single p as it is.
    assert float(doors["welch_p_holm"]) == pytest.approx(float(doors["welch_p"]))


def test_holm_by_hand() -> None:
    # Sorted 0.01, 0.03, 0.04 → 3·0.01, max(0.03, 2·0.03), max(0.06, 1·0.04); NaN is not a test.
    assert holm([0.01, 0.04, 0.03, float("nan")])[:3] == pytest.approx([0.03, 0.06, 0.06])
    assert math.isnan(holm([0.01, 0.04, 0.03, float("nan")])[3])


def _sweep(tmp_path: Path, means: dict[tuple[str, int], tuple[float, int]]) -> Path:
    """Five trials per condition spread ±2 s / ±1 door around the given means."""
    rows = []
    for (method, robots), (team, doors) in means.items():
        for i, (dt, dd) in enumerate(zip((-2, -1, 0, 1, 2), (-1, 0, 0, 0, 1))):
            rows.append(row(method, robots, i, team=team + dt, doors=doors + dd))
    write_trials(tmp_path, rows)
    return tmp_path


def test_claims_confirmed_when_arroch_is_lowest_everywhere(tmp_path: Path) -> None:
    folder = _sweep(tmp_path, {("arroch", 2): (600, 3), ("no-feedback", 2): (650, 6), ("no-comm", 2): (700, 9),
                               ("arroch", 3): (610, 3), ("no-feedback", 3): (660, 6), ("no-comm", 3): (710, 9)})
    verdicts = {c.title: c.verdict for c in check_claims(load_results(folder))}
    assert verdicts == {"Fewest door openings": "confirmed", "Lowest team completion time": "confirmed"}


def test_claims_not_hidden_when_a_baseline_wins_somewhere(tmp_path: Path) -> None:
    # At 3 robots no-comm is faster and needs as many openings as ARROCH.
    folder = _sweep(tmp_path, {("arroch", 2): (600, 3), ("no-comm", 2): (700, 9),
                               ("arroch", 3): (700, 9), ("no-comm", 3): (600, 9)})
    claims = {c.title: c for c in check_claims(load_results(folder))}
    assert claims["Lowest team completion time"].verdict == "partly confirmed"
    assert "3 robots: not confirmed" in claims["Lowest team completion time"].detail
    assert claims["Fewest door openings"].verdict == "partly confirmed"


def _laziness(tmp_path: Path, low_arroch: float, low_nocomm: float) -> Path:
    rows = []
    for p, arroch, nocomm in ((0.05, low_arroch, low_nocomm), (0.1, 620, 700), (0.5, 600, 700)):
        for method, team in (("arroch", arroch), ("no-comm", nocomm)):
            rows += [row(method, 3, i, p=p, team=team + dt, doors=4 if method == "arroch" else 9) for i, dt in enumerate((-2, -1, 0, 1, 2))]
    write_trials(tmp_path, rows)
    return tmp_path


def test_laziness_crossover(tmp_path: Path) -> None:
    claims = {c.title: c for c in check_claims(load_results(_laziness(tmp_path / "yes", 900, 700)))}
    assert claims["Laziness crossover"].verdict == "confirmed"
    assert "stays below no-comm's from p = 0.1 on" in claims["Laziness crossover"].detail
    claims = {c.title: c for c in check_claims(load_results(_laziness(tmp_path / "no", 650, 700)))}
    # ARROCH is fastest even for the laziest human: the paper's exception is not seen.
    assert claims["Laziness crossover"].verdict == "partly confirmed"
    assert "no-comm not significantly faster" in claims["Laziness crossover"].detail


def test_report_files(fixed: Path) -> None:
    (fixed / "discussion.md").write_text("Written by a person.\n", encoding="utf-8")
    written = {p.name for p in build_report(fixed)}
    assert {"summary.csv", "summary.md", "tests.csv", "REPORT.md", "door_openings_vs_robots.png",
            "team_completion_time_vs_robots.png"} <= written
    for name in ("door_openings_vs_robots.png", "team_completion_time_vs_robots.png"):
        assert (fixed / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (fixed / "REPORT.md").read_text(encoding="utf-8")
    assert "1 timeout" in report and "Written by a person." in report
    assert "### Fewest door openings: **cannot be checked**" not in report  # arroch and no-comm are there


def test_report_refuses_a_folder_without_results(tmp_path: Path) -> None:
    from services.experiments.results import ReportError

    with pytest.raises(ReportError, match="no trials.csv"):
        build_report(tmp_path)
