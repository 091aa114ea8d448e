"""The contact model: rows per contact (6 - d), zero at contact, analytic Jacobians."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixturecad.registration.contacts import ContactType, make_side, residuals_and_jacobian
from fixturecad.theory.instances import generic_instance
from paper import table_iii

CONTACTS = sorted(table_iii())
ORIENTED = [(name, swap) for name in CONTACTS for swap in (False, True)]


def _ctype(name, swap):
    ctype = ContactType.parse(name)
    return ctype.swapped() if swap else ctype


@pytest.mark.parametrize("name,swap", ORIENTED)
def test_rows_are_six_minus_the_printed_dimension_and_independent(name, swap):
    rng = np.random.default_rng(11)
    printed_dim = table_iii()[name][1]
    for _ in range(3):
        instance = generic_instance(_ctype(name, swap), rng)
        values, _ = instance.rows()
        wrenches = instance.wrenches()
        assert np.abs(values).max() < 1e-9
        assert wrenches.shape[0] == 6 - printed_dim
        assert np.linalg.matrix_rank(wrenches, tol=1e-8) == 6 - printed_dim


@pytest.mark.parametrize("name,swap", ORIENTED)
def test_analytic_jacobian_matches_finite_differences(name, swap):
    rng = np.random.default_rng(5)
    ctype = _ctype(name, swap)
    instance = generic_instance(ctype, rng)
    rotation = Rotation.from_rotvec(rng.normal(size=3) * 0.4).as_matrix()
    translation = rng.normal(size=3) * 10.0
    _, jacobian = residuals_and_jacobian(ctype, instance.sensor, instance.fixture, rotation, translation, instance.rho)
    step = 1e-6
    numeric = np.zeros_like(jacobian)
    for k in range(6):
        values = []
        for sign in (1, -1):
            twist = np.zeros(6)
            twist[k] = sign * step
            delta = Rotation.from_rotvec(twist[:3]).as_matrix()
            v, _ = residuals_and_jacobian(
                ctype, instance.sensor, instance.fixture, delta @ rotation, delta @ translation + twist[3:], instance.rho
            )
            values.append(v)
        numeric[..., k] = (values[0] - values[1]) / (2 * step)
    assert np.allclose(jacobian, numeric, atol=1e-6 * (1 + np.abs(numeric).max()))


def test_point_on_plane_residual_is_the_signed_distance():
    # A probe point 2 mm above the plane z = 5 of a fixture moved up by 1 mm.
    ctype = ContactType.parse("P/F-PL/M")
    sensor = make_side("P", True, c=[[3.0, 4.0, 8.0]], o=[[3.0, 4.0, 8.0]])
    fixture = make_side("PL", False, q=[0.0, 0.0, 5.0], n=[0.0, 0.0, 1.0])
    values, jacobian = residuals_and_jacobian(ctype, sensor, fixture, np.eye(3), [0.0, 0.0, 1.0])
    assert values.shape == (1, 1)
    assert values[0, 0] == pytest.approx(2.0)
    # Moving the fixture up brings the plane to the probe: the distance falls.
    assert np.allclose(jacobian[0, 0, 3:], [0.0, 0.0, -1.0])


def test_a_mobile_point_is_refused():
    with pytest.raises(ValueError, match="always fixed"):
        ContactType("P", False, "PL", True)


@pytest.mark.parametrize("text", ["P/F-X/M", "P/F", "P-F-PL/M", "P/Q-PL/M"])
def test_unreadable_contact_names_are_refused(text):
    with pytest.raises(ValueError, match="P/F-PL/M|elements are"):
        ContactType.parse(text)
