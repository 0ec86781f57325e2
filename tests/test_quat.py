import numpy as np
from scipy.spatial.transform import Rotation as R

from rtseg.core import quat
def test_multiply_matches_scipy_composition():
    a, b = R.random(50, random_state=1), R.random(50, random_state=2)
    np.testing.assert_allclose(quat.multiply(a.as_quat(), b.as_quat()), (a * b).as_quat(), atol=1e-12)


def test_from_euler_zyx_is_rz_ry_rx():
    ang = np.array([[10.0, -20.0, 33.0]])
    M = R.from_quat(quat.from_euler("ZYX", ang)).as_matrix()[0]
    expected = (R.from_euler("z", 10, degrees=True).as_matrix()
                @ R.from_euler("y", -20, degrees=True).as_matrix()
                @ R.from_euler("x", 33, degrees=True).as_matrix())
    np.testing.assert_allclose(M, expected, atol=1e-12)


def test_make_continuous_removes_sign_flips():
    q = R.from_euler("z", np.linspace(0, 90, 20)[:, None], degrees=True).as_quat()
    flipped = q.copy()
    flipped[5:12] *= -1
    fixed = quat.make_continuous(flipped[:, None, :])[:, 0]
    np.testing.assert_allclose(fixed, q, atol=1e-12)
    assert np.all(np.sum(fixed[1:] * fixed[:-1], axis=-1) > 0)


def test_local_global_round_trip():
    parents = [-1, 0, 1, 1]
    loc = R.random(40, random_state=3).as_quat().reshape(10, 4, 4)
    glob = quat.global_from_local(loc, parents)
    back = quat.local_from_global(glob, parents)
    # equal as rotations (q ~ -q)
    dots = np.abs(np.sum(back * loc, axis=-1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-12)
