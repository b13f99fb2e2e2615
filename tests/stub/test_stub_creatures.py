"""Creature generators (the creature report, docs/stub-tasks.md): reproducible MJCF, models that
load and rest, symmetry, limits."""
from __future__ import annotations

import subprocess
import sys

import mujoco
import numpy as np
import pytest

from tests.stub.conftest import REPO
from unity_stub_env.cli import main
from unity_stub_env.creatures import LIMITS, generate, to_mjcf
from unity_stub_env.creatures.lsystem import build_tree, derive
from unity_stub_env.creatures.skeleton import MIRROR

KINDS = ("quadruped", "biped", "lsystem")
SEEDS = range(12)


def test_cli_writes_the_same_bytes_for_the_same_seed(tmp_path):
    paths = [tmp_path / f"{name}.xml" for name in ("a", "b", "c")]
    assert main(["creature", "--kind", "quadruped", "--seed", "7", "--mjcf", str(paths[0])]) == 0
    assert main(["creature", "--kind", "quadruped", "--seed", "7", "--mjcf", str(paths[1])]) == 0
    assert main(["creature", "--kind", "quadruped", "--seed", "8", "--mjcf", str(paths[2])]) == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()
    for kind in KINDS:
        assert to_mjcf(generate(kind, 3)) == to_mjcf(generate(kind, 3))


def test_cli_entry_point_and_bad_output_path(tmp_path):
    out = tmp_path / "lsys.xml"
    done = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "creature", "--kind", "lsystem", "--seed", "7",
                           "--mjcf", str(out)], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert out.read_text() == to_mjcf(generate("lsystem", 7))
    bad = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "creature", "--mjcf", str(tmp_path / "no" / "x.xml")],
                         cwd=REPO, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--mjcf" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.parametrize("kind", KINDS)
def test_every_model_loads_and_rests_for_two_seconds(kind):
    """Zero controls hold the rest pose: 2 s of simulated time stay finite and slow; the parametric
    creatures stay upright (the L-system ones may topple: their limbs are not symmetric)."""
    for seed in SEEDS:
        model = mujoco.MjModel.from_xml_string(to_mjcf(generate(kind, seed)))
        data = mujoco.MjData(model)
        fastest = 0.0
        for _ in range(int(round(2.0 / model.opt.timestep))):
            mujoco.mj_step(model, data)
            fastest = max(fastest, float(np.abs(data.qvel).max()))
        assert np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all(), (kind, seed)
        assert fastest < 15.0, (kind, seed, fastest)
        lowest = min(data.geom_xpos[g, 2] - model.geom_size[g, 0] for g in range(1, model.ngeom))
        assert lowest > -0.05, (kind, seed, lowest)  # nothing sank through the floor
        if kind == "quadruped":
            assert data.xmat[1, 8] > 0.95, (kind, seed)  # the root's z axis stays up
        if kind == "biped":
            assert data.xmat[1, 8] > 0.6, (kind, seed)
        assert model.nu == generate(kind, seed).num_hinges()


@pytest.mark.parametrize("kind", ["quadruped", "biped"])
def test_limbs_are_mirror_symmetric_and_thickest_near_the_body(kind):
    for seed in SEEDS:
        skeleton = generate(kind, seed)
        bones = {b.name: b for b in skeleton.bones}
        left = [b for b in skeleton.bones if b.side == 1]
        assert len(left) == len([b for b in skeleton.bones if b.side == -1]) == (8 if kind == "quadruped" else 5)
        for bone in left:
            partner = bones[bone.name.replace("_l", "_r")]
            assert partner.side == -1 and partner.category == bone.category
            assert partner.length == pytest.approx(bone.length, abs=1e-12)
            assert partner.radius == bone.radius
            assert np.allclose(MIRROR @ partner.proximal, bone.proximal, atol=1e-12)
            assert np.allclose(MIRROR @ partner.distal, bone.distal, atol=1e-12)
            assert np.allclose(-(partner.axes() @ MIRROR.T), bone.axes(), atol=1e-12)
        legs = {}
        for bone in skeleton.bones:
            if bone.category in ("leg_upper", "leg"):
                legs.setdefault(bone.name.rstrip("0123456789"), []).append(bone.radius)
        assert len(legs) == (4 if kind == "quadruped" else 2)
        for radii in legs.values():
            assert len(radii) == (4 if kind == "quadruped" else 2)
            assert radii == sorted(radii, reverse=True)
        # in the compiled model, every pair of geoms has the same size and mirrored positions
        model = mujoco.MjModel.from_xml_string(to_mjcf(skeleton))
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        for bone in left:
            g_left, g_right = model.geom(bone.name).id, model.geom(bone.name.replace("_l", "_r")).id
            assert np.allclose(model.geom_size[g_left], model.geom_size[g_right], atol=1e-6)
            assert np.allclose(MIRROR @ data.geom_xpos[g_right], data.geom_xpos[g_left], atol=1e-5)


def test_parametric_structure_matches_the_creature_report():
    for seed in SEEDS:
        quad, biped = generate("quadruped", seed), generate("biped", seed)
        for skeleton in (quad, biped):
            categories = [b.category for b in skeleton.bones]
            assert categories.count("torso") == 3 and categories.count("head") == 1
            assert 1 <= categories.count("neck") <= 3
            assert skeleton.bones[0].category == "torso" and skeleton.bones[0].parent == -1
            necks = [b for b in skeleton.bones if b.category in ("neck", "head")]
            for a, b in zip(necks[1:-1], necks[2:-1]):  # neck turns within +-20 deg (the head extends the last)
                angle = np.degrees(np.arccos(np.clip(a.proximal_axis @ b.proximal_axis, -1, 1)))
                assert angle <= 20.0 + 1e-9
            assert np.allclose(necks[-1].proximal_axis, necks[-2].proximal_axis)
        q_categories = [b.category for b in quad.bones]
        assert q_categories.count("leg_upper") == 4 and q_categories.count("leg") == 12
        assert "arm" not in q_categories and "foot" not in q_categories
        b_categories = [b.category for b in biped.bones]
        assert b_categories.count("leg_upper") == 2 and b_categories.count("leg") == 2
        assert b_categories.count("foot") == 2 and b_categories.count("arm_upper") == 2
        # torso upright for the biped, (nearly) horizontal for the quadruped; feet level
        assert np.allclose(biped.bones[0].proximal_axis, [0, 0, 1])
        assert abs(quad.bones[0].proximal_axis[2]) < 0.5
        feet = [b.distal[2] - b.radius for b in quad.bones if b.name.endswith("3")]
        assert len(feet) == 4 and max(feet) - min(feet) < 0.05


@pytest.mark.parametrize("kind", KINDS)
def test_joint_limits_follow_the_bone_categories(kind):
    for seed in range(4):
        skeleton = generate(kind, seed)
        model = mujoco.MjModel.from_xml_string(to_mjcf(skeleton))
        expected = {}
        for bone in skeleton.bones[1:]:
            for axis, (low, high) in LIMITS[bone.category].items():
                expected[f"{bone.name}_{axis}"] = np.radians([low, high])
        hinges = [model.joint(j) for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        assert sorted(j.name for j in hinges) == sorted(expected)
        for joint in hinges:
            assert np.allclose(joint.range, expected[joint.name], atol=1e-6), joint.name
            assert model.jnt_limited[joint.id]
        rigid = [b.name for b in skeleton.bones if b.category in ("hip", "shoulder")]
        assert all(model.body(name).jntnum[0] == 0 for name in rigid)


def test_lsystem_tree_is_rebuilt_from_segment_endpoints():
    origin, x, y = np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    down = np.array([0, 0, -1.0])
    # drawn order: a neck leaving the torso's start, the torso, a hip at the torso's end, a leg
    segments = [(origin, -x, "n", down), (origin, x, "t", down), (x, x + y, "s", down), (x + y, x + y + down, "l", x)]
    bones = build_tree(segments)
    assert [b.category for b in bones] == ["torso", "neck", "hip", "leg_upper"]
    assert [b.parent for b in bones] == [-1, 0, 0, 2]
    text = derive(5)
    assert set(text) <= set("tsolanh+-&^|[]()0123456789.")
    for seed in SEEDS:
        skeleton = generate("lsystem", seed)
        for bone in skeleton.bones[1:]:
            parent = skeleton.bones[bone.parent]
            assert (np.allclose(bone.proximal, parent.distal) or
                    (bone.parent == 0 and np.allclose(bone.proximal, parent.proximal)))
        assert sum(b.category == "leg_upper" for b in skeleton.bones) >= 4
