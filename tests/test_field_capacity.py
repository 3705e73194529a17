"""scripts/field_capacity.py: the irreps an equivariant agent's layers hold fewer copies of
than they must pass on (issue 38's N-ball agents at linear width)."""

import importlib.util
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # builds the icosahedral group (tests/conftest.py: LARGE_GROUPS)

SPEC = importlib.util.spec_from_file_location(
    "field_capacity", Path(__file__).resolve().parent.parent / "scripts" / "field_capacity.py")
fc = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(fc)

POINTMASS3D = "GeoMDP/PointMass3D-v0"
CPU_PRESET = (128, 32, 128)  # encoder, latent, dynamics widths
VECTOR = (1,)  # escnn's id of the icosahedral and octahedral groups' vector irrep


@pytest.mark.parametrize("n_balls, width, expected", [
    # 1 ball: position and velocity (2 vectors), 1 action vector: everything fits
    (1, "linear", {"encoder hidden": (2, {}), "latent": (1, {}), "dynamics hidden": (2, {})}),
    # 5 balls: 10 state vectors, 5 action vectors; 2 fields hold 6 copies, 1 field 3
    (5, "linear", {"encoder hidden": (2, {VECTOR: (10, 6)}), "latent": (1, {VECTOR: (10, 3)}),
                   "dynamics hidden": (2, {VECTOR: (15, 6)})}),
    (5, "sqrt", {"encoder hidden": (17, {}), "latent": (4, {}), "dynamics hidden": (17, {})}),
])
def test_icosahedral_layers_against_n_balls(n_balls, width, expected):
    assert fc.shortfalls(POINTMASS3D, {"n_balls": n_balls}, "icosahedral", width,
                         *CPU_PRESET) == expected


def test_a_wider_latent_leaves_the_encoder_short():
    # issue 38's latent check (latent 240: 4 fields) at the CPU preset's encoder width
    table = fc.shortfalls(POINTMASS3D, {"n_balls": 5}, "icosahedral", "linear", 128, 240, 128)
    assert table["latent"] == (4, {}) and table["encoder hidden"] == (2, {VECTOR: (10, 6)})


def test_the_octahedral_agent_is_short_only_in_its_latent():
    table = fc.shortfalls(POINTMASS3D, {"n_balls": 5}, "octahedral", "linear", *CPU_PRESET)
    assert {layer: short for layer, (_, short) in table.items()} == {
        "encoder hidden": {}, "latent": {VECTOR: (10, 3)}, "dynamics hidden": {}}


def test_a_shortfall_the_headline_agent_learns_with():
    # D8 on Reacher hard, local frame: sin(theta2) and both joint velocities flip sign under
    # a reflection (a 1-dimensional irrep); the latent's 2 regular fields hold it twice.
    table = fc.shortfalls("GeoMDP/Reacher-v0", {"difficulty": "hard", "frame": "local"},
                          "D8", "linear", *CPU_PRESET)
    fields, short = table["latent"]
    assert fields == 2 and list(short.values()) == [(3, 2)]
    assert table["encoder hidden"][1] == {}


def test_task_values_are_read_as_geomdp_check_reads_them():
    assert fc.task(f"{POINTMASS3D}:n_balls=2,target_size=0.03,walls=true") == (
        POINTMASS3D, {"n_balls": 2, "target_size": 0.03, "walls": True})


def test_the_table_and_a_bad_task_spec(capsys):
    assert fc.main([f"{POINTMASS3D}:n_balls=2", "--groups", "octahedral"]) == 0
    row = "| GeoMDP/PointMass3D-v0 n_balls=2 | octahedral | linear | 5, none | 1, (1,): 4 vs 3 | 5, none |"
    assert row in capsys.readouterr().out
    with pytest.raises(SystemExit, match="'n_balls' in .* is not KEY=VALUE"):
        fc.main([f"{POINTMASS3D}:n_balls", "--groups", "octahedral"])
