"""Every shift changes what it claims, and shift specs serialise with a version."""

from __future__ import annotations

import numpy as np
import pytest

from nsl.collectors import STUDY_SEVERITIES, EnvConfig, GraspEnv, ShiftSpec, parse_shift, parse_shift_list
from nsl.errors import ConfigError, IncompatibleVersionError, UnknownReferenceError


@pytest.fixture(scope="module")
def frames():
    """First frames of the same four scenes under each shift, from the fixed shoulder camera (whole bin)."""
    out = {}
    for name in [
        "base",
        "harsh_lighting",
        "checkerboard_backing",
        "transparent_objects",
        "harsh_lighting+checkerboard_backing",
    ]:
        env = GraspEnv(EnvConfig(shift=name, camera="shoulder"))
        out[name] = np.stack([env.reset(seed=s)[0]["image"] for s in range(4)]).astype(np.float64)
        env.close()
    return out


def _floor(img):  # the bin interior in image coordinates (mostly floor; objects cover little of it)
    return img[:, 28:58, 12:52]


def test_harsh_lighting_brightens_and_saturates(frames):
    base, harsh = frames["base"], frames["harsh_lighting"]
    assert harsh.mean() > base.mean() + 15
    assert (harsh >= 250).mean() > (base >= 250).mean() + 0.05  # a saturated patch
    assert harsh.std() > base.std()  # harder light/dark contrast


def test_checkerboard_adds_black_and_white_squares(frames):
    base, checker = _floor(frames["base"]), _floor(frames["checkerboard_backing"])
    assert checker.std() > 2 * base.std()
    assert (checker.mean(-1) < 40).mean() > 0.2 and (checker.mean(-1) > 200).mean() > 0.2
    assert (base.mean(-1) < 40).mean() < 0.05 and (base.mean(-1) > 200).mean() < 0.05


def test_the_wrist_camera_sees_the_shifts_too():
    """The default wrist camera looks at the floor below the fingers: the checkerboard and the light show there."""

    def first_frames(shift):
        env = GraspEnv(EnvConfig(shift=shift))
        out = np.stack([env.reset(seed=s)[0]["image"] for s in range(4)]).astype(np.float64)
        env.close()
        return out

    base, checker, harsh = first_frames("base"), first_frames("checkerboard_backing"), first_frames("harsh_lighting")
    floor = np.s_[:, 40:, :]  # the lower part of the picture: the floor ahead of the finger tips
    assert checker[floor].std() > 2 * base[floor].std()
    assert harsh.mean() > base.mean() + 15


def test_shifts_compose(frames):
    both = frames["harsh_lighting+checkerboard_backing"]
    assert _floor(both).std() > 2 * _floor(frames["base"]).std()  # the checkerboard is there
    wall = np.s_[:, :, :8]  # the bin's left wall, outside the floor: lit by the harsh light either way
    assert both[wall].mean() > frames["checkerboard_backing"][wall].mean() + 20  # and so is the bright light


def test_transparent_objects_are_nearly_clear(frames):
    env = GraspEnv(EnvConfig(shift="transparent_objects"))
    env.reset(seed=0)
    m = env.model
    alphas = [m.geom_rgba[m.geom(f"object{i}").id, 3] for i in range(len(env.objects))]
    assert np.allclose(alphas, 0.15)
    env.close()
    # Opaque coloured objects stand out from the floor; clear ones barely do.
    diff_base = np.abs(frames["base"] - frames["base"].mean(axis=(1, 2), keepdims=True)).mean()
    diff_clear = np.abs(
        frames["transparent_objects"] - frames["transparent_objects"].mean(axis=(1, 2), keepdims=True)
    ).mean()
    assert diff_clear < diff_base


def _model(shift: str):
    env = GraspEnv(EnvConfig(shift=shift))
    env.reset(seed=0)
    m = env.model
    env.close()
    return m


def test_extend_gripper_makes_fingers_longer_and_narrower():
    base, ext = _model("base"), _model("extend_gripper")
    for side in ("left", "right"):
        b, e = base.geom(f"finger_{side}"), ext.geom(f"finger_{side}")
        assert e.size[2] * 2 == pytest.approx(b.size[2] * 2 + 0.01)  # 1 cm longer
        assert e.size[1] < b.size[1]  # narrower
        tip_b, tip_e = b.pos[2] - b.size[2], e.pos[2] - e.size[2]
        assert tip_e == pytest.approx(tip_b - 0.01)  # the tips reach 1 cm further down
    assert _model("extend_gripper@2").geom("finger_left").size[2] * 2 == pytest.approx(
        base.geom("finger_left").size[2] * 2 + 0.02
    )


def test_offset_gripper_moves_fingers_10cm_from_the_wrist():
    base, off = _model("base"), _model("offset_gripper")
    assert np.allclose(base.body("finger_mount").pos, 0)
    assert np.linalg.norm(off.body("finger_mount").pos[:2]) == pytest.approx(0.10)
    assert np.linalg.norm(_model("offset_gripper@0.5").body("finger_mount").pos[:2]) == pytest.approx(0.05)


def test_spec_json_round_trip_and_version():
    spec = parse_shift("harsh_lighting@1.5+checkerboard_backing")
    again = ShiftSpec.from_json(spec.to_json())
    assert again == spec and again.name == "harsh_lighting@1.5+checkerboard_backing"
    d = spec.to_dict()
    assert d["version"] == 1 and d["shifts"][0]["params"]["intensity"] == pytest.approx(15.0)
    d["version"] = 99
    with pytest.raises(IncompatibleVersionError, match="version 99"):
        ShiftSpec.from_dict(d)
    assert parse_shift("base").shifts == ()


def test_study_list_is_base_and_the_five_at_their_calibrated_severities():
    specs = parse_shift_list("study")
    assert specs[0] == parse_shift("base") and len(specs) == 6
    assert {s.shifts[0].name: s.shifts[0].severity for s in specs[1:]} == STUDY_SEVERITIES
    assert set(STUDY_SEVERITIES) == {n for n in parse_shift_list("all")[1:] for n in [n.shifts[0].name]}
    # severity 1 keeps its meaning: a calibrated shift is written with its @X
    assert parse_shift_list("harsh_lighting@2")[0] == specs[1] and specs[1].name == "harsh_lighting@2"


@pytest.mark.parametrize(
    "text,error,match",
    [
        ("harsh_lightning", UnknownReferenceError, "did you mean 'harsh_lighting'"),
        ("offset_gripper@7", ConfigError, r"out of range; use a value in \[0, 2.0\]"),
        ("offset_gripper@far", ConfigError, "not a number"),
    ],
)
def test_bad_shift_specs(text, error, match):
    with pytest.raises(error, match=match):
        parse_shift(text)
