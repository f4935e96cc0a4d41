"""CAP: a continuous fit of RULA that equals RULA at band midpoints, rises monotonically,
honours weights and power, and never turns missing joints into a number."""
import math

import numpy as np
import pytest

from edge_runtime.core.skeleton import INDEX
from edge_runtime.posture.cap import CapParams, cap_array, cap_score, cycle_cap, knee_penalty, part_curve
from firmware_sim.people.human import Body, Posture, joints

BODY = Body.from_height(1.75, "M")

# RULA bands as docs/design.md section 5 states them: (part, band midpoint in deg, RULA score)
RULA_MIDPOINTS = [
    ("upper_arm", 0.0, 1), ("upper_arm", 32.5, 2), ("upper_arm", 67.5, 3),
    ("lower_arm", 80.0, 1), ("lower_arm", 30.0, 2),
    ("neck", 5.0, 1), ("neck", 15.0, 2),
    ("trunk", 0.0, 1), ("trunk", 10.0, 2), ("trunk", 40.0, 3),
]


def pose(**kw) -> np.ndarray:
    """Joints of a posture; arms in front with elbows at 80 deg unless given."""
    base = dict(shoulder_flexion_deg=(0.0, 0.0), elbow_flexion_deg=(80.0, 80.0))
    base.update(kw)
    return joints(BODY, Posture(**base), (0.0, 1.0), math.pi)


@pytest.mark.parametrize("part,angle,rula", RULA_MIDPOINTS)
def test_cap_equals_rula_at_band_midpoints(part, angle, rula):
    assert part_curve(part, angle) == pytest.approx(rula)


def test_cap_lies_between_neighbouring_rula_scores_inside_bands():
    # inside the 45..90 deg upper-arm band CAP moves from 2.x to 3.x, never outside 2..4
    vals = part_curve("upper_arm", np.linspace(46, 89, 20))
    assert np.all(np.diff(vals) > 0) and vals.min() > 2 and vals.max() < 4


def test_angles_from_joints_recover_the_body_model_angles():
    j = pose(trunk_flexion_deg=25.0, neck_flexion_deg=15.0, shoulder_flexion_deg=(40.0, 40.0),
             elbow_flexion_deg=(70.0, 70.0), knee_flexion_deg=(30.0, 30.0), hip_flexion_deg=(15.0, 15.0))
    a = cap_score(j).angles
    assert a.trunk_flexion_deg == pytest.approx(25.0, abs=0.5)
    assert a.neck_flexion_deg == pytest.approx(15.0, abs=1.5)       # the crown sits ~1 deg ahead of the thorax
    assert a.upper_arm_flexion_deg == pytest.approx((40.0, 40.0), abs=0.5)
    assert a.elbow_flexion_deg == pytest.approx((70.0, 70.0), abs=0.5)
    assert a.knee_flexion_deg == pytest.approx((30.0, 30.0), abs=0.5)


def test_abduction_is_measured_and_raises_the_upper_arm_score():
    a0 = cap_score(pose(shoulder_abduction_deg=(0.0, 0.0)))
    a1 = cap_score(pose(shoulder_abduction_deg=(40.0, 40.0)))
    assert a1.angles.upper_arm_abduction_deg == pytest.approx((40.0, 40.0), abs=1.0)
    assert a1.parts["upper_arm"] > a0.parts["upper_arm"] + 0.5


@pytest.mark.parametrize("field,part", [("neck_flexion_deg", "neck"), ("trunk_flexion_deg", "trunk")])
def test_part_score_rises_with_flexion(field, part):
    scores = [cap_score(pose(**{field: a})).parts[part] for a in range(6, 60, 6)]
    assert np.all(np.diff(scores) > 0)


def test_extension_scores_like_flexion():
    flex = cap_score(pose(neck_flexion_deg=18.0)).parts["neck"]
    ext = cap_score(pose(neck_flexion_deg=-18.0)).parts["neck"]
    assert ext == pytest.approx(flex, abs=0.25)


def test_knee_penalty_is_zero_to_20_deg_then_linear_to_4():
    assert knee_penalty(15.0) == 0.0
    assert knee_penalty(30.0) == pytest.approx(2.0)
    assert knee_penalty(60.0) == pytest.approx(4.0)
    squat = cap_score(pose(knee_flexion_deg=(60.0, 60.0), hip_flexion_deg=(30.0, 30.0)))
    assert squat.parts["knee"] == pytest.approx(4.0, abs=0.05)


def test_weights_scale_their_part_only():
    j = pose(neck_flexion_deg=20.0, trunk_flexion_deg=15.0)
    base = cap_score(j)
    doubled = cap_score(j, CapParams(neck_weight=2.0))
    assert doubled.cap - base.cap == pytest.approx(base.parts["neck"])
    only_trunk = cap_score(j, CapParams(neck_weight=0, upper_arm_weight=0, lower_arm_weight=0, knee_weight=0))
    assert only_trunk.cap == pytest.approx(base.parts["trunk"])


@pytest.mark.parametrize("power", [2, 3])
def test_power_sums(power):
    j = pose(neck_flexion_deg=30.0, trunk_flexion_deg=30.0)
    r = cap_score(j, CapParams(power=power))
    assert r.cap == pytest.approx(sum(v ** power for v in r.parts.values()))
    # a square sum punishes one bad part more than the linear sum does
    assert r.cap > cap_score(j).cap


def test_missing_joint_gives_an_invalid_result_naming_it():
    j = pose()
    j[INDEX["left_wrist"]] = np.nan
    r = cap_score(j)
    assert not r.valid and math.isnan(r.cap) and "left_wrist" in r.reason
    assert math.isnan(cap_array(j))
    j2 = pose()
    j2[INDEX["head"], 1] = np.inf
    assert "head" in cap_score(j2).reason


def test_cycle_with_too_few_valid_frames_is_invalid():
    frames = np.stack([pose() for _ in range(6)])
    frames[:4, INDEX["right_elbow"]] = np.nan
    r = cycle_cap(frames)
    assert not r.valid and "2 of 6" in r.reason
    frames[:2] = pose()
    assert cycle_cap(frames).valid


def test_bad_params_name_the_key():
    with pytest.raises(ValueError, match="power"):
        CapParams(power=4)
    with pytest.raises(ValueError, match="neck_weight"):
        CapParams(neck_weight=-1.0)
