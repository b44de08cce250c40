"""Hypothesis strategies: random but valid trajectories for critic-vs-reference checks."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from robocritics.trajectory import Pair, Step
from synth import frames_from, make_trajectory

ENTITIES = ("apple", "box", "table", "")
ARM_LINKS = ("forearm_link", "wrist_1_link", "wrist_3_link")
GRIPPER_PARTS = ("gripper_body", "left_finger")


@st.composite
def trajectories(draw, max_samples: int = 40):
    """A random trajectory: 1-4 frames (the last is ``tcp``), 0-7 tagged pairs, 1-3 steps
    with random contacts, runs of attached objects, even or uneven sample times."""
    T = draw(st.integers(1, max_samples))
    L = draw(st.integers(1, 4))
    K = draw(st.integers(0, 7))
    S = draw(st.integers(1, 3))
    speed = draw(st.sampled_from([0.05, 0.3, 0.8, 1.2, 2.5]))  # m/s scale of the motion
    reach = draw(st.sampled_from([0.1, 0.3, 0.6]))  # m scale of the start positions
    uneven = draw(st.booleans())
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)

    if uneven:
        dt = rng.uniform(0.002, 0.05, T - 1)
    else:
        dt = np.full(T - 1, 1.0 / float(rng.choice([125.0, 500.0])))
    time = np.concatenate([[0.0], np.cumsum(dt)]) + rng.uniform(0, 3)

    start = rng.uniform(-reach, reach, (1, L, 3)) + np.array([0.0, 0.0, 0.15])
    vel = rng.normal(size=(max(T - 1, 0), L, 3)) * speed / np.sqrt(3)
    pos = np.concatenate([start, start + np.cumsum(vel * dt[:, None, None], axis=0)], axis=0)
    z_axes = rng.normal(size=(T, L, 3))
    z_axes[np.linalg.norm(z_axes, axis=-1) < 1e-3] = (0.0, 0.0, -1.0)
    frames = frames_from(pos, z_axes)

    wq = rng.normal(size=(max(T - 1, 0), 6)) * speed * 3
    q = np.concatenate([np.zeros((1, 6)), np.cumsum(wq * dt[:, None], axis=0)], axis=0)

    pairs = []
    for k in range(K):
        kind = draw(st.sampled_from(["self", "environment"]))
        if kind == "self":
            a = draw(st.sampled_from(ARM_LINKS))
            b = draw(st.sampled_from(ARM_LINKS + GRIPPER_PARTS))
            pairs.append(Pair(name=f"p{k}", kind="self", a=a, b=b, group_a="arm", group_b="gripper" if b in GRIPPER_PARTS else "arm"))
        else:
            ga = draw(st.sampled_from(["arm", "gripper", "attached"]))
            a = {"arm": "forearm_link", "gripper": "left_finger", "attached": "apple"}[ga]
            ent = draw(st.sampled_from(ENTITIES))
            gb = "table" if ent == "table" else draw(st.sampled_from(["object", "container"]))
            pairs.append(Pair(name=f"p{k}", kind="environment", a=a, b=ent or "wall", group_a=ga, group_b=gb, b_entity=ent))
    proximity = rng.uniform(-0.03, 0.12, (T, K))

    steps = []
    for i in range(S):
        contacts = tuple(e for e in ENTITIES[:3] if draw(st.booleans()))
        steps.append(Step(skill=draw(st.sampled_from(["move_to", "move_down", "close_gripper"])), line=2 + i, contacts=contacts))
    step = np.sort(rng.integers(0, S, T))
    held_choices = np.array(["", "apple", "box"])
    cuts = np.sort(rng.integers(0, T + 1, 2))
    attached = np.empty(T, dtype=object)
    attached[: cuts[0]] = held_choices[rng.integers(0, 3)]
    attached[cuts[0] : cuts[1]] = held_choices[rng.integers(0, 3)]
    attached[cuts[1] :] = held_choices[rng.integers(0, 3)]

    names = tuple(f"link_{i}" for i in range(L - 1)) + ("tcp",)
    return make_trajectory(
        time,
        frames=frames,
        frame_names=names,
        proximity=proximity,
        pairs=pairs,
        q=q,
        steps=steps,
        step=step,
        attached=[str(a) for a in attached],
    )
