"""The arm of examples/real_arm.yaml, as a user runs it: a three-link arm read from its URDF,
with joint damping and Coulomb friction, striking a plate on a compliant mount, seen through an
encoder. Each part has its own tests; these check that they work together."""

import os

REAL_ARM = os.path.join(os.path.dirname(__file__), '..', 'examples', 'real_arm.yaml')


def test_a_urdf_arm_takes_a_mounted_plate_and_joint_friction():
    """The mount's contact-time check takes the contact sphere's radius from the URDF (a URDF
    scene has no ``tip_radius`` key)."""
    from impact_arm.physics.scene import load_scene

    scene = load_scene(REAL_ARM)
    assert scene.general_links and scene.tip_radius == 0.005
    assert scene.surfaces[0].mount is not None and scene.surfaces[0].mount.mass == 10.0
    assert [j.friction for j in scene.joints] == [0.2, 0.3, 0.1]
