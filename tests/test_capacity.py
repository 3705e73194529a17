"""Whether an equivariant agent's layers can carry the task's state (agents.nn.capacity,
scripts/field_capacity.py, and geomdp-train's warning), counted for issue 38's N-ball agents."""


import gymnasium
import pytest
from conftest import load_script
from test_train import config

import geomdp_envs  # noqa: F401  (registers the tasks)
from agents.cli.train import run
from agents.nn.capacity import encoder_shortfall, shortfalls
from agents.nn.networks import Architecture, NetworkConfig

pytestmark = pytest.mark.slow  # builds the icosahedral group (tests/conftest.py: LARGE_GROUPS)

fc = load_script("scripts/field_capacity.py")

POINTMASS3D = "GeoMDP/PointMass3D-v0"
VECTOR = (1,)  # escnn's id of the icosahedral and octahedral groups' vector irrep


def symmetry(env_id=POINTMASS3D, **kwargs):
    return gymnasium.make(env_id, **kwargs).unwrapped.symmetry


def agent(group, width="linear", hidden=128, latent=32, encoder=None, **kwargs):
    """The CPU preset's widths unless told."""
    return NetworkConfig(group=group, width_strategy=width, networks=Architecture(
        hidden_dim=hidden, latent_dim=latent, encoder_dim=encoder), **kwargs)


@pytest.mark.parametrize("n_balls, width, expected", [
    # 1 ball: position and velocity (2 vectors), 1 action vector: everything fits
    (1, "linear", {"encoder hidden": (2, {}), "latent": (1, {}), "dynamics hidden": (2, {})}),
    # 5 balls: 10 state vectors, 5 action vectors; 2 fields hold 6 copies, 1 field 3
    (5, "linear", {"encoder hidden": (2, {VECTOR: (10, 6)}), "latent": (1, {VECTOR: (10, 3)}),
                   "dynamics hidden": (2, {VECTOR: (15, 6)})}),
    (5, "sqrt", {"encoder hidden": (17, {}), "latent": (4, {}), "dynamics hidden": (17, {})}),
])
def test_icosahedral_layers_against_n_balls(n_balls, width, expected):
    assert shortfalls(agent("icosahedral", width), symmetry(n_balls=n_balls)) == expected


def test_a_wider_latent_leaves_the_encoder_short():
    # issue 38's latent check (latent 240: 4 fields) at the CPU preset's encoder width
    table = shortfalls(agent("icosahedral", latent=240), symmetry(n_balls=5))
    assert table["latent"] == (4, {}) and table["encoder hidden"] == (2, {VECTOR: (10, 6)})


def test_the_octahedral_agent_is_short_only_in_its_latent():
    table = shortfalls(agent("octahedral"), symmetry(n_balls=5))
    assert {layer: short for layer, (_, short) in table.items()} == {
        "encoder hidden": {}, "latent": {VECTOR: (10, 3)}, "dynamics hidden": {}}


def test_a_latent_shortfall_the_headline_agent_learns_with():
    # D8 on Reacher hard, local frame: sin(theta2) and both joint velocities flip sign under
    # a reflection (a 1-dimensional irrep); the latent's 2 regular fields hold it twice.
    table = shortfalls(agent("D8"), symmetry("GeoMDP/Reacher-v0", difficulty="hard"))
    fields, short = table["latent"]
    assert fields == 2 and list(short.values()) == [(3, 2)]
    assert table["encoder hidden"][1] == {}


def test_the_encoder_warning_names_the_shortfall_and_a_width_that_fits():
    five_balls = symmetry(n_balls=5)
    message = encoder_shortfall(agent("icosahedral"), five_balls)
    assert message == ("agent.group=icosahedral at width_strategy=linear: the encoder's hidden "
                       "layers (2 fields) hold 6 of the observation's 10 copies of irrep (1,), so "
                       "part of the state never reaches the agent; agent.networks.encoder_dim=210 "
                       "or more fits it (scripts/field_capacity.py)")
    assert encoder_shortfall(agent("icosahedral", encoder=210), five_balls) is None
    assert shortfalls(agent("icosahedral", encoder=209), five_balls)["encoder hidden"][1]
    # nothing to warn of: the octahedral encoder fits; a plain agent or a plain encoder
    assert encoder_shortfall(agent("octahedral"), five_balls) is None
    assert encoder_shortfall(agent(None), five_balls) is None
    plain_transition = dict(equivariant={"transition": False, "q": False, "policy": False})
    assert encoder_shortfall(agent("icosahedral", **plain_transition), five_balls) is None


def test_the_trainer_warns_of_an_encoder_too_narrow_and_trains(tmp_path):
    # Reacher hard, local frame: 3 sign fields (D8's irrep (1, 0)); the tiny test agent's 16
    # hidden units are one D8 field, which holds 1 (the CPU preset's 128 are 8 fields)
    with pytest.warns(UserWarning) as record:
        assert run(config("env=reacher", "env.difficulty=hard", "agent.group=D8",
                          "agent.width_strategy=linear", "train.steps=1000"), tmp_path) == 0
    assert [str(w.message) for w in record] == [
        "agent.group=D8 at width_strategy=linear: the encoder's hidden layers (1 field) hold 1 of "
        "the observation's 3 copies of irrep (1, 0), so part of the state never reaches the agent; "
        "agent.networks.encoder_dim=41 or more fits it (scripts/field_capacity.py)"]


def test_task_values_are_read_as_geomdp_check_reads_them():
    assert fc.task(f"{POINTMASS3D}:n_balls=2,target_size=0.03,walls=true") == (
        POINTMASS3D, {"n_balls": 2, "target_size": 0.03, "walls": True})


def test_the_table_and_a_bad_task_spec(capsys):
    assert fc.main([f"{POINTMASS3D}:n_balls=2", "--groups", "octahedral"]) == 0
    row = "| GeoMDP/PointMass3D-v0 n_balls=2 | octahedral | linear | 5, none | 1, (1,): 4 vs 3 | 5, none |"
    assert row in capsys.readouterr().out
    with pytest.raises(SystemExit, match="in .*: 'n_balls' is not KEY=VALUE"):
        fc.main([f"{POINTMASS3D}:n_balls", "--groups", "octahedral"])
