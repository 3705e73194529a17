"""scripts/latent_capacity.py: the irreps an equivariant latent holds fewer of than the
observation (issue 38's N-ball agents at linear width)."""

import importlib.util
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # builds the icosahedral group (tests/conftest.py: LARGE_GROUPS)

SPEC = importlib.util.spec_from_file_location(
    "latent_capacity", Path(__file__).resolve().parent.parent / "scripts" / "latent_capacity.py")
lc = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(lc)

POINTMASS3D = "GeoMDP/PointMass3D-v0"


@pytest.mark.parametrize("n_balls, width, fields, short", [
    (1, "linear", 1, {}),                      # position and velocity: 2 of the 3 copies
    (5, "linear", 1, {(1,): (10, 3)}),         # 10 vectors through 3 copies
    (5, "sqrt", 4, {}),                        # 4 fields: 12 copies
])
def test_icosahedral_latent_against_n_balls(n_balls, width, fields, short):
    assert lc.shortfalls(POINTMASS3D, {"n_balls": n_balls}, "icosahedral", width, 32) == (fields, short)


def test_a_shortfall_the_headline_agent_learns_with():
    # D8 on Reacher hard, local frame: sin(theta2) and both joint velocities flip sign under
    # a reflection (a 1-dimensional irrep); 2 regular fields hold it twice.
    fields, short = lc.shortfalls("GeoMDP/Reacher-v0", {"difficulty": "hard", "frame": "local"},
                                  "D8", "linear", 32)
    assert fields == 2 and list(short.values()) == [(3, 2)]


def test_task_values_are_read_as_geomdp_check_reads_them():
    assert lc.task(f"{POINTMASS3D}:n_balls=2,target_size=0.03,walls=true") == (
        POINTMASS3D, {"n_balls": 2, "target_size": 0.03, "walls": True})


def test_the_table_and_a_bad_task_spec(capsys):
    assert lc.main([f"{POINTMASS3D}:n_balls=2", "--groups", "octahedral"]) == 0
    row = "| GeoMDP/PointMass3D-v0 n_balls=2 | octahedral | linear | 1 | (1,): 4 vs 3 |"
    assert row in capsys.readouterr().out
    with pytest.raises(SystemExit, match="'n_balls' in .* is not KEY=VALUE"):
        lc.main([f"{POINTMASS3D}:n_balls", "--groups", "octahedral"])
