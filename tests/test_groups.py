import numpy as np
import pytest

from geomdp_envs import groups


@pytest.mark.parametrize("name, order", [
    ("C4", 4), ("C8", 8), ("D4", 8), ("D8", 16), ("D16", 32), ("octahedral", 24),
    ("full_octahedral", 48), ("icosahedral", 60), ("full_icosahedral", 120),
])
def test_finite_groups_are_closed_orthogonal_and_of_the_right_order(name, order):
    elements = groups.group_elements(name)
    assert len(elements) == order
    d = groups.group_dim(name)
    for g in elements:
        np.testing.assert_allclose(g @ g.T, np.eye(d), atol=1e-12)
    products = elements[:, None] @ elements[None, :]
    for p in products.reshape(-1, d, d)[:: max(1, order // 7)]:
        assert groups.contains(name, p)


def test_rotation_groups_have_only_proper_rotations():
    for name in ("C8", "octahedral", "icosahedral"):
        assert np.allclose(np.linalg.det(groups.group_elements(name)), 1)


def test_d4_and_full_octahedral_are_the_signed_permutations():
    for name in ("D4", "full_octahedral"):
        for g in groups.group_elements(name):
            assert np.allclose(np.sort(np.abs(g), axis=None)[-len(g):], 1)
            assert np.allclose(np.abs(g).sum(axis=0), 1)


def test_membership_and_subgroups():
    assert groups.contains("D8", groups.rotation_2d(np.pi / 4))
    assert not groups.contains("D4", groups.rotation_2d(np.pi / 4))
    assert groups.contains("D4", np.diag([1.0, -1.0]))
    assert not groups.contains("C4", np.diag([1.0, -1.0]))
    assert not groups.contains("SO(3)", -np.eye(3))
    assert groups.is_subgroup("D4", "D8") and not groups.is_subgroup("D8", "D4")
    assert groups.is_subgroup("icosahedral", "SO(3)") and groups.is_subgroup("SO(2)", "O(2)")
    assert not groups.is_subgroup("full_octahedral", "SO(3)")
    assert not groups.is_subgroup("D4", "O(3)")


@pytest.mark.parametrize("name", ["O(2)", "SO(2)", "O(3)", "SO(3)", "D8", "icosahedral"])
def test_samples_belong_to_the_group(name):
    samples = groups.sample(name, np.random.default_rng(0), 20)
    assert samples.shape == (20, groups.group_dim(name), groups.group_dim(name))
    assert all(groups.contains(name, g) for g in samples)
    if name.startswith("O("):  # both components are reached
        assert {np.sign(np.linalg.det(g)) for g in samples} == {-1.0, 1.0}


def test_bad_input_gives_clear_errors():
    with pytest.raises(ValueError, match="unknown group 'Q8'.*valid groups"):
        groups.group_dim("Q8")
    with pytest.raises(ValueError, match="must be a 2x2 matrix"):
        groups.as_orthogonal(np.eye(3), 2)
    with pytest.raises(ValueError, match="orthogonal"):
        groups.as_orthogonal(2 * np.eye(2), 2)
    with pytest.raises(ValueError, match="continuous"):
        groups.group_elements("SO(3)")
