"""The analysis's engineering in the engine: the verdicts and their findings (engine.design.verdicts), the
choice of a combination (engine.structure.loads.pick_combination) and the load test (engine.design.load_test)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.design.load_test import load_test, permanent_and_variable
from engine.design.verdicts import Verdict, VerdictFixes, design_verdicts, findings_of
from engine.errors import InputError
from engine.structure.frame import FrameModel
from engine.structure.loads import LimitState, LoadCase, LoadCombination, pick_combination
from engine.structure.protocol import ImperfectionCase
from engine.structure.supports import Supports

FIXES = VerdictFixes(stiffer="stiffer", deflection="stiffer or a looser limit", buckling_not_solved="check supports",
                     path_stopped="the solver stopped")


def _displacements(uz: list[float]) -> np.ndarray:
    out = np.zeros((len(uz), 6))
    out[:, 2] = uz
    return out


def _verdicts(*, utilisation=(0.2, 0.5), uz=(0.0, -0.01), limit=0.02, lambda_LB=3.0, error=None, worst=None):
    return design_verdicts(utilisation=np.array(utilisation), sls_displacements=_displacements(list(uz)),
                           deflection_limit=limit, deflection_ratio=250, required_load_factor=1.5,
                           lambda_LB=lambda_LB, buckling_error=error, worst=worst, fixes=FIXES)


def _case(capacity: float, limit_point: bool = True, name: str = "mode1-") -> ImperfectionCase:
    return ImperfectionCase(name=name, limit_load_factor=capacity if limit_point else None,
                            path=np.array([[0.0, 0.0], [capacity, -0.1]]))


def test_a_verdict_passes_exactly_at_its_limit():
    at_limit = _verdicts(utilisation=(0.3, 1.0), uz=(-0.02, 0.01), limit=0.02, lambda_LB=1.5, worst=_case(1.5))
    assert [v.kind for v in at_limit] == ["utilisation", "deflection", "buckling", "nonlinear_buckling"]
    assert all(v.passed for v in at_limit)
    assert findings_of(at_limit) == []
    over = _verdicts(utilisation=(0.3, 1.0 + 1e-12), uz=(-0.0200001, 0.0), limit=0.02, lambda_LB=1.4999,
                     worst=_case(1.4999))
    assert not any(v.passed for v in over)


def test_verdicts_name_the_governing_parts_and_values():
    verdicts = _verdicts(utilisation=(0.2, 0.9, 0.4), uz=(0.001, -0.015, 0.003), worst=_case(2.0, False, "linear+"))
    utilisation, deflection, buckling, nonlinear = verdicts
    assert (utilisation.part, utilisation.value, utilisation.limit) == ("B0002", 0.9, 1.0)
    assert (deflection.part, deflection.value, deflection.unit) == ("N0002", 0.015, "m")
    assert deflection.check == "deflection (SLS) vs span/250"
    assert (buckling.part, buckling.value, buckling.limit) == ("mode 1", 3.0, 1.5)
    assert nonlinear.check == "worst non-linear load factor carried (no limit point found) (linear+)"
    assert (nonlinear.part, nonlinear.value) == ("linear+", 2.0)
    assert [v.fix for v in verdicts] == ["stiffer", "stiffer or a looser limit", "stiffer", "stiffer"]


def test_a_path_stopped_at_the_tolerable_deflection_is_judged_there_not_at_the_load_it_carried():
    """A soft roof hanging as a net carries 10 times the load metres out of shape: its capacity is
    the load factor where it reached the tolerable deflection, and the verdict says so."""
    net = ImperfectionCase(name="mode2+", limit_load_factor=None, tolerable_load_factor=0.4,
                           path=np.array([[0.0, 0.0], [0.4, -0.7], [10.0, -1.3]]))
    assert net.capacity == 0.4
    nonlinear = _verdicts(worst=net)[-1]
    assert not nonlinear.passed and nonlinear.value == 0.4
    assert nonlinear.check == ("worst non-linear load factor at the tolerable deflection "
                               "(no limit point before it) (mode2+)")


def test_a_path_whose_solver_stopped_is_no_buckling_load():
    """A path whose corrector did not converge at its first step carried 0: that is the solver's
    limit, not the structure's, so it fails as a stopped path with the solver's fix, not as a
    buckling load with "stiffer"; one that stopped above the required factor passes on its lower bound."""
    stopped = ImperfectionCase(name="linear+", limit_load_factor=None, converged=False, path=np.array([[0.0, 0.0]]))
    nonlinear = _verdicts(worst=stopped)[-1]
    assert (nonlinear.kind, nonlinear.value, nonlinear.passed) == ("nonlinear_path_stopped", 0.0, False)
    assert nonlinear.check == "worst non-linear load factor carried before its path stopped unconverged (linear+)"
    (finding,) = findings_of([nonlinear])
    assert finding.kind == "nonlinear_path_stopped" and finding.fix == "the solver stopped"
    late = ImperfectionCase(name="mode1+", limit_load_factor=None, converged=False,
                            path=np.array([[0.0, 0.0], [2.5, -0.1]]))
    passed = _verdicts(worst=late)[-1]
    assert passed.passed and passed.kind == "nonlinear_buckling" and passed.value == 2.5
    buckled = ImperfectionCase(name="mode1+", limit_load_factor=1.2, converged=False,
                               path=np.array([[0.0, 0.0], [1.2, -0.1], [1.1, -0.2]]))
    assert _verdicts(worst=buckled)[-1].kind == "nonlinear_buckling", "a limit point found is a buckling load"


def test_a_buckling_analysis_that_did_not_solve_fails_with_its_error():
    verdicts = _verdicts(lambda_LB=None, error="no eigenvalue converged")
    assert [v.kind for v in verdicts] == ["utilisation", "deflection", "buckling_not_solved"]
    (finding,) = findings_of(verdicts, stage="analysis")
    assert finding.kind == "buckling_not_solved" and finding.measure is None and finding.limit == 1.5
    assert finding.message == "no eigenvalue converged" and finding.fix == "check supports"
    assert finding.parts == ["mode 1"] and finding.stage == "analysis"


def test_findings_only_for_failing_verdicts():
    verdicts = _verdicts(utilisation=(1.25, 0.5), uz=(-0.001, 0.0), lambda_LB=1.2, worst=_case(2.0))
    findings = findings_of(verdicts, stage="analysis")
    assert [f.kind for f in findings] == ["utilisation", "buckling"]
    assert findings[0].to_dict() == {"kind": "utilisation", "parts": ["B0001"], "measure": 1.25, "limit": 1.0,
                                     "unit": "", "message": "member utilisation (ULS): 1.25 against 1",
                                     "fix": "stiffer", "stage": "analysis"}
    assert findings[1].message == "linear buckling load factor: 1.2 against 1.5"


def test_a_finding_with_a_unit_says_it_in_its_message():
    """A deflection finding reads "0.06 m against 0.04 m", not two bare numbers."""
    verdicts = _verdicts(utilisation=(0.5, 0.5), uz=(-0.06, 0.0), lambda_LB=3.0, worst=_case(2.0))
    (finding,) = findings_of(verdicts, stage="analysis")
    assert finding.kind == "deflection" and finding.unit == "m"
    assert finding.message.endswith(f"{finding.measure:.3g} m against {finding.limit:.3g} m")


def test_verdict_records_keep_the_keys_of_analysis_json():
    verdicts = _verdicts(error="not solved", worst=_case(1.0))
    records = [v.to_dict() for v in verdicts]
    assert [list(r) for r in records] == [
        ["check", "kind", "value", "limit", "pass", "part", "fix"],
        ["check", "kind", "value", "limit", "pass", "unit", "part", "fix"],
        ["check", "kind", "value", "limit", "part", "pass", "error", "fix"],
        ["check", "kind", "value", "limit", "part", "pass", "fix"],
        ["check", "kind", "value", "limit", "part", "pass", "fix"],
    ]
    assert records[4] == {"check": "worst non-linear limit load factor (mode1-)", "kind": "nonlinear_buckling",
                          "value": 1.0, "limit": 1.5, "part": "mode1-", "pass": False, "fix": "stiffer"}
    assert Verdict(check="c", kind="k", value=1.0, limit=2.0, passed=True, part="p").to_dict()["pass"] is True


COMBINATIONS = {
    "SLS char": LoadCombination(name="SLS char", limit_state=LimitState.SLS, factors={"dead": 1.0, "snow": 1.0}),
    "ULS 1": LoadCombination(name="ULS 1", limit_state=LimitState.ULS, factors={"dead": 1.35, "snow": 1.5}),
    "ULS 2": LoadCombination(name="ULS 2", limit_state=LimitState.ULS, factors={"dead": 1.0}),
}
CASES = {"dead": LoadCase(name="dead", self_weight=1.0), "snow": LoadCase(name="snow", area_plan=[0, 0, -800.0])}


def test_pick_combination_takes_the_named_one_or_the_first_of_its_limit_state():
    assert pick_combination(COMBINATIONS, CASES, "ULS") is COMBINATIONS["ULS 1"]
    assert pick_combination(COMBINATIONS, CASES, LimitState.SLS) is COMBINATIONS["SLS char"]
    assert pick_combination(COMBINATIONS, CASES, "ULS", "ULS 2") is COMBINATIONS["ULS 2"]


def test_pick_combination_of_a_load_case_alone_or_of_every_case():
    alone = pick_combination(COMBINATIONS, CASES, "SLS", "snow")
    assert (alone.name, alone.limit_state, alone.factors) == ("snow", LimitState.SLS, {"snow": 1.0})
    only_sls = {"SLS char": COMBINATIONS["SLS char"]}
    for name in (None, "unknown"):
        every = pick_combination(only_sls, CASES, "ULS", name)
        assert (every.name, every.limit_state, every.factors) == ("ULS", LimitState.ULS, {"dead": 1.0, "snow": 1.0})


E, I, A = 2.0e11, 1.0e-6, 1.0e-3
LENGTH, N_BEAMS = 2.0, 4
DEAD, TEST = 20.0, 10.0   # N at the tip: self-weight (held) and the test load (increased)


def _cantilever() -> tuple[FrameModel, Supports]:
    nodes = np.c_[np.linspace(0.0, LENGTH, N_BEAMS + 1), np.zeros(N_BEAMS + 1), np.zeros(N_BEAMS + 1)]
    model = FrameModel(nodes=nodes, beams=np.c_[np.arange(N_BEAMS), np.arange(1, N_BEAMS + 1)], E=E, G=E / 2.6,
                       A=A, Iy=I, Iz=I, J=2 * I, up=np.array([0.0, 0.0, 1.0]))
    return model, Supports(nodes=np.array([0]), restraints=np.ones((1, 6), bool))


def _tip_loads(case: LoadCase) -> np.ndarray:
    """The case's point loads, and its self-weight as DEAD N down at the tip."""
    loads = case.point_load_array(N_BEAMS + 1)
    loads[N_BEAMS, 2] -= DEAD * case.self_weight
    return loads


def test_the_load_test_of_a_cantilever_follows_the_beam_formula():
    """A cantilever with its self-weight held and a test load at the tip increased: at small
    deflections each control node moves as P x^2 (3L - x) / (6EI) with P the tip load."""
    model, supports = _cantilever()
    cases = {"dead": LoadCase(name="dead", self_weight=1.0),
             "test": LoadCase(name="test", point_nodes=[N_BEAMS], point_forces=[[0, 0, -TEST, 0, 0, 0]])}
    combination = LoadCombination(name="SLS", limit_state=LimitState.SLS, factors={"dead": 1.0, "test": 2.0})
    points = {"tip": [LENGTH + 0.05, 0.02, 0.0], "middle": [0.5 * LENGTH - 0.1, 0.0, 0.01]}
    test = load_test(model, supports, cases, combination, points, _tip_loads, max_load_factor=3.0)
    assert test is not None
    assert (test.permanent, test.variable) == ({"dead": 1.0}, {"test": 2.0})
    assert test.control_nodes == {"tip": N_BEAMS, "middle": N_BEAMS // 2}
    assert test.converged and test.limit_load_factor is None
    assert test.largest_load_factor == pytest.approx(3.0)
    assert test.load_factors[0] == 0.0 and len(test.load_factors) > 2
    assert test.monitored.shape == (len(test.path), 2)
    assert test.path[:, 1] == pytest.approx(test.monitored[:, 0], abs=0)

    def beam(x: float, load_factor: np.ndarray) -> np.ndarray:
        tip_load = DEAD + 2.0 * TEST * load_factor
        return -tip_load * x**2 * (3 * LENGTH - x) / (6 * E * I)

    for column, x in enumerate((LENGTH, 0.5 * LENGTH)):
        assert test.monitored[:, column] == pytest.approx(beam(x, test.load_factors), rel=1e-4)
    record = test.to_dict()
    assert record == {"permanent_cases": ["dead"], "variable_cases": ["test"],
                      "control_nodes": {"tip": "N0005", "middle": "N0003"}, "limit_load_factor": None,
                      "largest_load_factor": test.largest_load_factor, "path_complete": True}


def test_a_load_test_needs_a_variable_case_and_a_control_point():
    model, supports = _cantilever()
    cases = {"dead": LoadCase(name="dead", self_weight=1.0), "snow": LoadCase(name="snow", area_plan=[0, 0, -1.0])}
    held = LoadCombination(name="SLS", limit_state=LimitState.SLS, factors={"dead": 1.0})
    assert permanent_and_variable(held, cases) == ({"dead": 1.0}, {})
    assert load_test(model, supports, cases, held, {"tip": [LENGTH, 0, 0]}, _tip_loads, max_load_factor=2.0) is None
    with pytest.raises(InputError, match="control point"):
        load_test(model, supports, cases, held, {}, _tip_loads, max_load_factor=2.0)
