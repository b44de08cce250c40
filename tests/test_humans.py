"""People in scenes: validation of Scene.humans, the ISO/TS 15066 limits worked by hand, the capsule body model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.critic.builtin.cobot import robot_masses
from robocritics.errors import SceneError
from robocritics.humans import BODY_REGIONS, body_model, reduced_mass_kg, transient_speed_limit
from robocritics.robot.model import Robot
from robocritics.scene import Human, Scene

# ISO/TS 15066:2016 Annex A, per region: quasi-static force F (N, Table A.2), transient contact permitted,
# spring constant k (N/mm, Annex A), effective mass m_H (kg, Table A.3), and v_max (m/s) for the bundled UR3e
# (moving mass M = 8.7985 kg, UR's published link masses; tool 1.0 kg) with nothing carried, worked by hand:
#   m_R = M/2 + m_L = 4.39925 + 1.0 = 5.39925 kg;  mu = (1/m_H + 1/m_R)^-1;  v_max = 2F / sqrt(mu k)
# e.g. abdomen: mu = (1/40 + 1/5.39925)^-1 = 4.7571 kg, sqrt(4.7571 * 10000) = 218.11, v = 220 / 218.11 = 1.009.
HAND_WORKED = {
    "skull_forehead": (130, False, 150, 4.4, 0.0),
    "face": (65, False, 75, 4.4, 0.0),
    "neck": (150, True, 50, 1.2, 1.354),
    "back_shoulders": (210, True, 35, 40, 1.029),
    "chest": (140, True, 25, 40, 0.812),
    "abdomen": (110, True, 10, 40, 1.009),
    "pelvis": (180, True, 25, 40, 1.044),
    "upper_arms": (150, True, 30, 3, 1.247),
    "lower_arms": (160, True, 40, 2, 1.324),
    "hands": (140, True, 75, 0.6, 1.391),
    "thighs_knees": (220, True, 50, 75, 0.877),
    "lower_legs": (130, True, 60, 75, 0.473),
}


def test_the_table_has_the_twelve_regions_of_annex_a():
    assert set(BODY_REGIONS) == set(HAND_WORKED)


def test_the_bundled_ur3e_moves_its_published_link_masses_and_a_one_kilogram_gripper():
    moving, tool = robot_masses(Robot.ur3e())
    assert moving == pytest.approx(1.98 + 3.4445 + 1.437 + 0.871 + 0.805 + 0.261)
    assert tool == pytest.approx(1.0)


@pytest.mark.parametrize("name", sorted(HAND_WORKED))
def test_speed_limit_per_region_worked_by_hand(name):
    force, permitted, k_n_mm, m_h, v_hand = HAND_WORKED[name]
    region = BODY_REGIONS[name]
    assert (region.force_n, region.contact_permitted, region.spring_n_m, region.mass_kg) == (
        force, permitted, k_n_mm * 1000, m_h)
    v = transient_speed_limit(region, moving_mass_kg=8.7985, payload_kg=1.0)
    assert v == pytest.approx(v_hand, abs=0.0005)
    if permitted:  # the formula itself, independently: v = F_t / sqrt(mu k)
        mu = 1 / (1 / m_h + 1 / (8.7985 / 2 + 1.0))
        assert v == pytest.approx(2 * force / math.sqrt(mu * k_n_mm * 1000), rel=1e-12)
        # a heavier payload lowers the limit (m_R grows)
        assert transient_speed_limit(region, 8.7985, 4.0) < v


def test_reduced_mass_is_the_harmonic_combination():
    assert reduced_mass_kg(40.0, 40.0) == pytest.approx(20.0)
    assert reduced_mass_kg(1e9, 5.0) == pytest.approx(5.0)


def test_body_model_is_scaled_posed_and_covers_every_region():
    op = Human(id="op", position=(1.0, 2.0), yaw_rad=math.pi / 2, height_m=1.75, floor_z_m=-0.9)
    body = body_model(op)
    assert set(body.regions) == set(BODY_REGIONS)
    top = np.max(np.maximum(body.p0[:, 2], body.p1[:, 2]) + body.radius_m)
    assert top == pytest.approx(-0.9 + 1.75, abs=0.01)  # the head's top at the stature
    bottom = np.min(np.minimum(body.p0[:, 2], body.p1[:, 2]) - body.radius_m)
    assert -0.9 <= bottom < -0.9 + 0.05  # down to the ankles
    hands = [i for i, r in enumerate(body.regions) if r == "hands"]
    # facing +y: the hands reach forward along +y from the feet, at elbow height
    assert np.all(body.p1[hands, 1] > 2.0 + 0.4) and np.allclose(body.p1[hands, 0], 1.0 + np.array([1, -1]) * -0.2266, atol=0.01)
    tall = body_model(op.model_copy(update={"height_m": 2.0}))
    assert np.max(tall.p1[:, 2]) > np.max(body.p1[:, 2])
    seated = body_model(op.model_copy(update={"posture": "seated"}))
    head = body.names.index("skull_forehead")
    assert seated.p1[head, 2] < body.p1[head, 2] - 0.3


@pytest.mark.parametrize(
    "human, field",
    [
        ({"posture": "lying"}, "humans[0].posture"),
        ({"height_m": 3.0}, "humans[0].height_m"),
        ({"height_m": 0.5}, "humans[0].height_m"),
        ({"height_m": "tall"}, "humans[0].height_m"),
        ({"position": [0.5]}, "humans[0].position[1]"),
        ({"floor_z_m": float("inf")}, "humans[0].floor_z_m"),
        ({"id": "table"}, "humans[0].id"),
        ({"hat": True}, "humans[0].hat"),
    ],
)
def test_a_bad_person_is_a_scene_error_naming_the_field(human, field):
    data = {"humans": [{"id": "op", "position": [0.6, 0.0], **human}]}
    with pytest.raises(SceneError) as info:
        Scene.model_validate(data)
    assert info.value.path == field, str(info.value)


def test_person_ids_are_unique_among_all_entities():
    with pytest.raises(SceneError, match="duplicate id"):
        Scene.model_validate({"objects": [{"id": "op", "shape": "sphere", "size": [0.02], "position": [0.3, 0, 0.02]}],
                              "humans": [{"id": "op", "position": [0.6, 0.0]}]})


def test_the_cli_exits_2_on_a_bad_posture(tmp_path):
    import subprocess
    import sys

    scene = Scene.builtin("workbench").model_dump(mode="json")
    scene["humans"][0]["posture"] = "kneeling"
    path = tmp_path / "bad.json"
    import json

    path.write_text(json.dumps(scene))
    program = tmp_path / "p.py"
    program.write_text("home()\n")
    out = subprocess.run([sys.executable, "-m", "robocritics", "check", str(program), "--scene", str(path)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "humans[0].posture" in out.stderr


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-2, 2), y=st.floats(-2, 2), yaw=st.floats(-math.pi, math.pi), height=st.floats(1.4, 2.1),
    floor=st.floats(-1.2, 0.0), posture=st.sampled_from(["standing", "seated"]),
)
def test_body_model_is_the_upright_model_turned_and_moved_to_the_feet(x, y, yaw, height, floor, posture):
    """Reference: each capsule of a person at the origin facing +x, rotated by yaw about z, then translated."""
    here = body_model(Human(id="p", position=(x, y), yaw_rad=yaw, height_m=height, floor_z_m=floor, posture=posture))
    origin = body_model(Human(id="p", position=(0.0, 0.0), yaw_rad=0.0, height_m=height, floor_z_m=0.0,
                              posture=posture))
    c, s = math.cos(yaw), math.sin(yaw)
    for a, b in ((here.p0, origin.p0), (here.p1, origin.p1)):
        for got, ref in zip(a, b):
            turned = (c * ref[0] - s * ref[1] + x, s * ref[0] + c * ref[1] + y, ref[2] + floor)
            assert got == pytest.approx(turned, abs=1e-9)
    assert here.radius_m.tolist() == origin.radius_m.tolist()
    # taller people have proportionally larger bodies
    assert max(here.radius_m) == pytest.approx(0.065 * height)
