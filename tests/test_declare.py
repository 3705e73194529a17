"""Bring your own task: declarations of third-party envs, checked against MuJoCo."""

import pathlib

import gymnasium
import numpy as np
import pytest
import yaml
from omegaconf import OmegaConf
from test_train import config, rows

from agents.cli.train import run
from agents.run.config import RunOptions
from agents.run.envs import make_gym_env
from geomdp_envs import check_symmetry, declare, groups, load_declaration, symmetry_of
from geomdp_envs.check_cli import main as check_main
from geomdp_envs.declare import SHIPPED, Declaration, shipped_declarations

REACHER = load_declaration("reacher_v5")
PENDULUM = load_declaration("inverted_pendulum_v5")


def reacher(declaration=REACHER):
    return declare(gymnasium.make("Reacher-v5"), declaration)


def with_field(declaration, kind, name, **changes):
    data = declaration.to_dict()
    (entry,) = [f for f in data[kind] if f["name"] == name]
    entry.update(changes)
    return data


@pytest.fixture(scope="module")
def upright_pendulum_xml(tmp_path_factory):
    """Gymnasium's inverted pendulum with its pole upright instead of tilted 1.7 mrad."""
    source = pathlib.Path(gymnasium.__file__).parent / "envs/mujoco/assets/inverted_pendulum.xml"
    text = source.read_text()
    assert text.count('fromto="0 0 0 0.001 0 0.6"') == 1
    path = tmp_path_factory.mktemp("xml") / "upright.xml"
    path.write_text(text.replace('fromto="0 0 0 0.001 0 0.6"', 'fromto="0 0 0 0 0 0.6"'))
    return str(path)


def test_non_contiguous_fields_are_reordered_into_the_declared_layout():
    env = reacher()
    sym = env.symmetry
    assert [(f.name, f.rep, f.start, f.stop) for f in sym.observation[:3]] == [
        ("upper_arm_direction", "vector", 0, 2), ("cos_elbow", "trivial", 2, 3),
        ("sin_elbow", "sign", 3, 4)]
    raw_env = gymnasium.make("Reacher-v5")
    obs, _ = env.reset(seed=3)
    raw, _ = raw_env.reset(seed=3)
    np.testing.assert_array_equal(obs, raw[[0, 2, 1, 3, 4, 5, 6, 7, 8, 9]])
    # (cos q1, sin q1) is now one vector: rotating it by g is rotating the arm
    assert env.observation_space.shape == (10,) and env.observation_space.contains(obs)
    action = np.array([0.3, -0.7], dtype=np.float32)
    np.testing.assert_array_equal(env.step(action)[0],
                                  raw_env.step(action)[0][[0, 2, 1, 3, 4, 5, 6, 7, 8, 9]])


def test_actions_are_reordered_back_for_the_env():
    swapped = with_field(REACHER, "action", "shoulder_torque", index=1)
    swapped["action"][1]["index"] = 0
    env = reacher(swapped)
    np.testing.assert_array_equal(env.to_env_action(np.array([1.0, 2.0])), [2.0, 1.0])
    raw_env = gymnasium.make("Reacher-v5")
    env.reset(seed=0)
    raw_env.reset(seed=0)
    obs = env.step(np.array([0.5, -0.25]))[0]
    np.testing.assert_array_equal(obs, env.to_declared_observation(raw_env.step(np.array([-0.25, 0.5]))[0]))


def test_the_reacher_v5_declaration_passes_on_o2_and_its_subgroups():
    env = reacher()
    for group in ("O(2)", "D8", "C4"):
        report = check_symmetry(env, group=group, n_trials=16)
        assert report.passed, str(report)
        assert report.max_error < 1e-12


@pytest.mark.parametrize("name, rep, culprit", [
    ("shoulder_velocity", "trivial", "shoulder_velocity"),  # the sign trap
    ("sin_elbow", "trivial", "sin_elbow"),
    ("cos_elbow", "sign", "cos_elbow"),
])
def test_a_wrong_observation_field_fails_and_is_named(name, rep, culprit):
    report = check_symmetry(reacher(with_field(REACHER, "observation", name, rep=rep)), n_trials=16)
    assert not report.passed
    assert report.failing_fields[0] == culprit and report.field_errors[culprit] > 1e-2
    assert f"fields over tolerance: {culprit} " in str(report)


def test_wrong_indices_and_a_wrong_action_are_caught():
    # (cos q1, cos q2) is no vector: the observation itself is wrong
    data = with_field(REACHER, "observation", "upper_arm_direction", index=[0, 1])
    data = with_field(Declaration.from_dict(data), "observation", "cos_elbow", index=2)
    report = check_symmetry(reacher(data), n_trials=16)
    assert not report.passed and "upper_arm_direction" in report.failing_fields
    # a torque declared invariant: obs(g.s) matches, the steps after it do not
    report = check_symmetry(reacher(with_field(REACHER, "action", "shoulder_torque", rep="trivial")),
                            n_trials=16)
    assert report.max_observation_error < 1e-12 and report.max_next_observation_error > 1e-2
    assert "the action declaration" in str(report)


def test_a_wrong_state_declaration_fails():
    data = REACHER.to_dict()
    data["state"]["qpos"][0]["rep"] = "sign"  # the shoulder is an orientation, not a pseudo-scalar
    report = check_symmetry(reacher(data), group="SO(2)", n_trials=16)
    assert not report.passed and "upper_arm_direction" in report.failing_fields


def test_inverted_pendulum_mirror_is_exact_only_for_an_upright_pole(upright_pendulum_xml):
    assert PENDULUM.exact_group == "C1"  # the shipped model's pole is tilted
    stock = declare(gymnasium.make("InvertedPendulum-v5"), PENDULUM)
    report = check_symmetry(stock, group="D1", n_trials=16)
    assert not report.passed and 1e-4 < report.max_error < 0.1, str(report)
    assert report.max_observation_error == 0  # the mirror image of a state is observed exactly
    assert check_symmetry(stock).passed  # on its exact group C1, trivially
    upright = declare(gymnasium.make("InvertedPendulum-v5", xml_file=upright_pendulum_xml), PENDULUM)
    report = check_symmetry(upright, group="D1", n_trials=16)
    assert report.passed and report.max_error < 1e-12, str(report)
    wrong = declare(gymnasium.make("InvertedPendulum-v5", xml_file=upright_pendulum_xml),
                    with_field(PENDULUM, "observation", "pole_angle", rep="trivial"))
    report = check_symmetry(wrong, group="D1", n_trials=16)
    assert report.failing_fields[0] == "pole_angle"


def test_checking_restores_the_env_and_its_random_generator():
    env = reacher()
    env.reset(seed=1)
    before = env.simulator().get_state()
    check_symmetry(env, n_trials=4)
    after = env.simulator().get_state()
    np.testing.assert_array_equal(before.qpos, after.qpos)
    np.testing.assert_array_equal(before.qvel, after.qvel)
    twin = reacher()
    twin.reset(seed=1)
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])  # same next episode


class LinePlant(gymnasium.Env):
    """A 1D plant with no MuJoCo state to set: x' = x + a."""

    def __init__(self, low=-1.0):
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (1,), np.float64)
        self.action_space = gymnasium.spaces.Box(np.float32(low), np.float32(1), (1,), np.float32)
        self.x = np.zeros(1)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = self.np_random.normal(size=1)
        return self.x.copy(), {}

    def step(self, action):
        self.x = self.x + action
        return self.x.copy(), -float(abs(self.x[0])), False, False, {}


LINE = {"dim": 2, "continuous_group": "O(2)", "exact_group": "D1",
        "observation": [{"name": "x", "rep": "sign", "index": 0}],
        "action": [{"name": "push", "rep": "sign", "index": 0}]}


def test_actuator_activations_are_refused_by_the_check(tmp_path):
    """A filtered actuator carries state (MuJoCo's act) that no declaration moves."""
    source = pathlib.Path(gymnasium.__file__).parent / "envs/mujoco/assets/reacher.xml"
    motor = '<motor ctrllimited="true" ctrlrange="-1.0 1.0" gear="200.0" joint="joint0"/>'
    text = source.read_text()
    assert text.count(motor) == 1
    (tmp_path / "filtered.xml").write_text(text.replace(
        motor, motor.replace("<motor", "<general").replace("/>", ' dyntype="filter" dynprm="0.05"/>')))
    env = declare(gymnasium.make("Reacher-v5", xml_file=str(tmp_path / "filtered.xml")), REACHER)
    assert env.unwrapped.model.na == 1
    with pytest.raises(ValueError, match="has 1 actuator activation state.*cannot move them"):
        check_symmetry(env)


def test_an_env_whose_state_cannot_be_set_gets_a_clear_error():
    env = declare(LinePlant(), LINE)
    with pytest.raises(ValueError, match="has no state, so check_symmetry cannot move the simulator"):
        check_symmetry(env)
    env = declare(LinePlant(), {**LINE, "state": {"qpos": [{"name": "x", "rep": "sign", "index": 0}]}})
    with pytest.raises(TypeError, match="is not a Gymnasium MujocoEnv .*lacks model, data"):
        check_symmetry(env)
    assert symmetry_of(gymnasium.wrappers.ClipAction(env)) is env.symmetry  # still trains
    with pytest.raises(TypeError, match="declares no symmetry: wrap it with geomdp_envs.declare"):
        check_symmetry(LinePlant())


def test_a_state_declaration_must_cover_qpos_and_qvel():
    data = REACHER.to_dict()
    del data["state"]["qvel"][2]
    with pytest.raises(ValueError, match=r"Reacher-v5: state.qvel indices \[2, 3\] belong to no field"):
        check_symmetry(reacher(data))


@pytest.mark.parametrize("change, message", [
    (lambda d: d["observation"].pop(), r"observation indices \[8, 9\] belong to no field"),
    (lambda d: d["observation"][1].update(index=0), r"observation indices \[0\] belong to more than one"),
    (lambda d: d["observation"][1].update(index=12), r"observation indices \[12\] are out of range"),
    (lambda d: d["observation"][0].update(index=[0]), "a vector of R\\^2 has 2 coordinate"),
    (lambda d: d["observation"][0].update(rep="angle"), "unknown representation 'angle'; valid: trivial"),
    (lambda d: d["observation"][0].update(index="0"), "index must be an int or a non-empty list of ints"),
    (lambda d: d.update(colour="red"), r"unknown key\(s\) \['colour'\]"),
    (lambda d: d.update(exact_group="D4", continuous_group="SO(2)"), "D4 is not a subgroup of SO\\(2\\)"),
    (lambda d: d["state"].update(qacc=[]), r"state: unknown vector\(s\) \['qacc'\]; valid: qpos, qvel"),
    (lambda d: d["observation"][0].pop("rep"), "needs exactly the keys name, rep, index"),
    (lambda d: d["observation"][5].update(name="shoulder_velocity"),
     r"observation: field name\(s\) \['shoulder_velocity'\] used twice"),
    (lambda d: d.update(dim="two"), "dim must be 2 or 3, got 'two'"),
    (lambda d: d.update(dim=2.7), "dim must be 2 or 3, got 2.7"),
    (lambda d: d.update(dim=[2]), r"dim must be 2 or 3, got \[2\]"),
    (lambda d: d.update(continuous_group=2), "continuous_group must be a group name such as O\\(2\\), got 2"),
    (lambda d: d.update(exact_group=None), "exact_group must be a group name"),
    (lambda d: d["observation"][1].update(index=1.0), "index must be an int or a non-empty list of ints"),
    (lambda d: d["observation"][1].update(index=None), "index must be an int or a non-empty list of ints"),
    (lambda d: d["observation"][1].update(index="12"), "index must be an int or a non-empty list of ints"),
    (lambda d: d["observation"][1].update(index=[]), "index must be an int or a non-empty list of ints"),
    (lambda d: d["observation"][1].update(rep=3), "name and rep must be strings"),
    (lambda d: d.update(state=[1]), "state must map qpos and qvel to their fields"),
])
def test_bad_declarations_are_refused_with_the_problem_named(change, message):
    data = REACHER.to_dict()
    change(data)
    with pytest.raises(ValueError, match=message):
        reacher(data)


@pytest.mark.parametrize("key, valid", [
    ("dim", r"\(valid: 2, 3\)"),
    ("continuous_group", r"\(valid: O\(2\), SO\(2\), O\(3\), SO\(3\)\)"),
    ("exact_group", r"\(the subgroup of continuous_group .*C1 if none; valid: O\(2\), SO\(2\), "
                    r"C<N>, D<N> \(planar\); O\(3\), SO\(3\), octahedral"),
    ("observation", r"\(a list of fields \{name, rep, index\}\)"),
])
def test_a_declaration_states_every_required_key(key, valid):
    """No defaults: dim, the groups, observation and action are stated, in YAML, as plain
    data and as declare's keywords; the error names the key and its valid values."""
    data = REACHER.to_dict()
    del data[key]
    message = f"^declaration: missing key '{key}' {valid}"
    with pytest.raises(ValueError, match=message):
        Declaration.from_dict(data)
    with pytest.raises(ValueError, match=message):
        reacher(data)
    with pytest.raises(ValueError, match=message):
        declare(gymnasium.make("Reacher-v5"), **data)


def test_missing_keys_are_named_together_on_one_line(tmp_path):
    path = tmp_path / "partial.yaml"
    path.write_text(yaml.safe_dump({k: v for k, v in REACHER.to_dict().items()
                                    if k not in ("dim", "exact_group")}))
    with pytest.raises(ValueError) as err:
        load_declaration(str(path))
    (line,) = str(err.value).splitlines()
    assert line.startswith("declaration: missing keys 'dim' (valid: 2, 3), 'exact_group' (the subgroup")
    # what declare() used to fill in (dim 2, O(2), exact group = continuous group) is not assumed
    with pytest.raises(ValueError, match="^declaration: missing keys 'dim' .*, 'continuous_group' .*, "
                                         "'exact_group'"):
        declare(LinePlant(), observation=LINE["observation"], action=LINE["action"])
    assert declare(LinePlant(), **LINE).declaration == load_declaration(LINE)


def test_shipped_declarations_state_dim_and_exact_group():
    for name in shipped_declarations():
        data = yaml.safe_load((SHIPPED / f"{name}.yaml").read_text())
        assert {"dim", "continuous_group", "exact_group"} <= set(data), name


def test_action_bounds_must_be_symmetric_for_signed_fields():
    with pytest.raises(ValueError, match="'push' is sign but its bounds .* are not symmetric about 0"):
        declare(LinePlant(low=0.0), LINE)


def test_declare_refuses_a_task_that_declares_its_own_symmetry_and_double_specification():
    with pytest.raises(ValueError, match="declares a symmetry already"):
        declare(gymnasium.make("GeoMDP/Reacher-v0"), REACHER)
    with pytest.raises(TypeError, match="not both"):
        declare(gymnasium.make("Reacher-v5"), REACHER, dim=2)


def test_keyword_declaration_tuples_and_yaml_files_give_the_same_declaration(tmp_path):
    path = tmp_path / "reacher.yaml"
    path.write_text(yaml.safe_dump(REACHER.to_dict()))
    assert load_declaration(str(path)) == REACHER
    as_tuples = {k: [(f.name, f.rep, list(f.index)) for f in getattr(REACHER, k)]
                 for k in ("observation", "action")}
    env = declare(gymnasium.make("Reacher-v5"), dim=2, continuous_group="O(2)", exact_group="O(2)",
                  notes=REACHER.notes, state=REACHER.to_dict()["state"], **as_tuples)
    assert env.declaration == REACHER
    assert set(shipped_declarations()) >= {"reacher_v5", "inverted_pendulum_v5"}
    with pytest.raises(ValueError, match="neither a YAML file nor a shipped declaration .*reacher_v5"):
        load_declaration("reacher_v6")


def test_state_transform_moves_the_arm_angle_as_an_orientation():
    g = groups.rotation_2d(0.5)
    moved = REACHER.transform_state({"qpos": np.array([0.25, 0.1, 0.1, 0.0]),
                                     "qvel": np.array([1.0, 2.0, 0.0, 0.0])}, g)
    np.testing.assert_allclose(moved["qpos"], [0.75, 0.1, 0.1 * np.cos(0.5), 0.1 * np.sin(0.5)])
    mirror = np.diag([1.0, -1.0])
    moved = REACHER.transform_state({"qpos": np.array([0.25, 0.1, 0.1, 0.2]),
                                     "qvel": np.array([1.0, 2.0, 0.0, 0.0])}, mirror)
    np.testing.assert_allclose(moved["qpos"], [-0.25, -0.1, 0.1, -0.2])
    np.testing.assert_allclose(moved["qvel"], [-1.0, -2.0, 0.0, 0.0])


# --- training an agent on a declared third-party env (geomdp-train env.symmetry=...) ------


REACHER_V5 = ["env=gym", "env.id=Reacher-v5", "env.symmetry=reacher_v5", "env.action_repeat=2",
              "train.steps=300", "train.seed_steps=100", "train.eval_every=300"]


@pytest.mark.slow
def test_equivariant_agent_trains_on_a_declared_third_party_env(tmp_path):
    assert run(config(*REACHER_V5, "agent.group=D8"), tmp_path) == 0
    # config.yaml records the declaration's contents, not its name (a later edit of the file
    # cannot change what a resumed run uses)
    recorded = OmegaConf.to_container(OmegaConf.load(tmp_path / "config.yaml"))["env"]["symmetry"]
    assert recorded == load_declaration("reacher_v5").to_dict()
    assert [int(r["env_step"]) for r in rows(tmp_path / "eval.csv")] == [0, 300]
    # 50-step episodes at action repeat 2: two random episodes (50 updates at the end of
    # seeding, one per agent step of it), then an episode per 25 updates.
    # It learned: Q starts at exactly 0 (a zero output layer) and moves toward the TD
    # targets, which are negative (Reacher-v5's reward is -distance - |action|^2).
    train = rows(tmp_path / "train.csv")[1:]
    assert [int(r["updates"]) for r in train] == [50, 25, 25, 25, 25]
    q = [float(r["q_mean"]) for r in train]
    assert q[-1] < q[0] < 0 and all(float(r["td_target_mean"]) < 0 for r in train), train
    # the checkpoint holds D8-equivariant networks and the run continues from it
    assert run(config(*REACHER_V5, "agent.group=D8", "train.steps=400"), tmp_path) == 0
    assert [int(r["env_step"]) for r in rows(tmp_path / "eval.csv")][-1] == 400


@pytest.mark.slow
def test_reflection_agent_and_augmentation_on_the_inverted_pendulum(tmp_path):
    pendulum = ["env=gym", "env.id=InvertedPendulum-v5", "env.symmetry=inverted_pendulum_v5",
                "env.action_repeat=1", "train.steps=200", "train.seed_steps=100", "train.eval_every=200"]
    with pytest.warns(UserWarning, match="D1 is only an approximate symmetry of InvertedPendulum-v5 "
                                         r"\(exact group: C1\)"):
        assert run(config(*pendulum, "agent.group=D1"), tmp_path / "d1") == 0
    assert rows(tmp_path / "d1/train.csv")[-1]["q_mean"] != "0.0"
    # a plain agent with replay moved by the exact group (here trivial, C1): runs, no-op
    assert run(config(*pendulum, "agent.augment=auto"), tmp_path / "aug") == 0


@pytest.mark.parametrize("overrides, message", [
    (["env.symmetry=reacher_v6"], "env.symmetry: symmetry declaration 'reacher_v6' is neither a YAML "
                                  "file nor a shipped declaration"),
    (["env.id=Pendulum-v1", "env.symmetry=reacher_v5"],
     "env.symmetry: Pendulum-v1: observation indices [3, 4, 5, 6, 7, 8, 9] are out of range"),
    (["env.symmetry=5"], "env.symmetry must be a mapping or a string, got 5"),
    (["env.id=InvertedPendulum-v5", "+env.xml_file=/nowhere/pendulum.xml"], "/nowhere/pendulum.xml"),
    (["env.id=InvertedPendulum-v5", "agent.group=O2"],
     "O2 is only an approximate symmetry of InvertedPendulum-v5 (exact group: C1); set "
     "agent.allow_approximate=true"),
])
def test_bad_declarations_on_the_command_line_give_one_line(tmp_path, capsys, overrides, message):
    base = ["env=gym", "env.id=Reacher-v5", "env.symmetry=reacher_v5"]
    if "env.id=InvertedPendulum-v5" in overrides:
        base[2] = "env.symmetry=inverted_pendulum_v5"
    assert run(config(*base, *overrides), tmp_path / "run") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "run").exists()


def test_geomdp_check_reports_and_exits_by_verdict(tmp_path, capsys, upright_pendulum_xml):
    assert check_main(["Reacher-v5", "reacher_v5", "--group", "O(2)", "D8", "--trials", "8"]) == 0
    out = capsys.readouterr().out
    assert "| observation | [0:2] | upper_arm_direction | vector |" in out
    assert "PASS O(2): 8 trials" in out and "PASS D8: 8 trials" in out
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(yaml.safe_dump(with_field(PENDULUM, "observation", "pole_angle", rep="trivial")))
    assert check_main(["InvertedPendulum-v5", str(wrong), "--group", "D1", "--trials", "8",
                       "--kwarg", f"xml_file={upright_pendulum_xml}"]) == 1
    assert "fields over tolerance: pole_angle" in capsys.readouterr().out
    for argv, message in [(["Pendulum-v1"], "Pendulum-v1 declares no symmetry: give a declaration"),
                          (["Reacher-v5", "reacher_v5", "--group", "Q3"], "unknown group 'Q3'"),
                          (["Reacher-v6", "reacher_v5"], "unknown environment 'Reacher-v6'"),
                          (["InvertedPendulum-v5", "inverted_pendulum_v5", "--kwarg",
                            "xml_file=/nowhere/pendulum.xml"], "/nowhere/pendulum.xml"),
                          (["Reacher-v5", "reacher_v5", "--trials", "0"], "n_trials and n_steps")]:
        assert check_main(argv) == 2
        (line,) = capsys.readouterr().err.strip().splitlines()
        assert line.startswith("geomdp-check: error: ") and message in line
    with pytest.raises(SystemExit) as exit_info:  # argparse's own exit: status 2, one line
        check_main(["Reacher-v5", "reacher_v5", "--kwarg", "xml_file"])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "geomdp-check: error: argument --kwarg: 'xml_file' is not KEY=VALUE")


def test_unreadable_declarations_and_direct_construction(tmp_path):
    broken = tmp_path / "broken.yaml"
    broken.write_text("dim: 2\nobservation: [ {name: x\n")
    with pytest.raises(ValueError, match="symmetry declaration .*broken.yaml' cannot be read: while parsing"):
        load_declaration(str(broken))
    direct = Declaration(2, "O(2)", "D1", observation=[("x", "sign", 0)], action=[("push", "sign", 0)])
    assert direct.observation[0].index == (0,)  # tuples are parsed as from_dict's fields are
    assert declare(LinePlant(), direct).symmetry.observation_size == 1


def test_a_wrapper_under_declare_is_refused_by_the_check():
    swap = gymnasium.wrappers.TransformObservation(gymnasium.make("Reacher-v5"), lambda o: o[::-1], None)
    env = declare(swap, REACHER)
    with pytest.raises(ValueError, match="TransformObservation sits between declare\\(\\) and the env"):
        check_symmetry(env)
    with pytest.raises(ValueError, match="declares a symmetry already"):
        declare(env, REACHER)
    with pytest.raises(ValueError, match="n_trials and n_steps must be at least 1, got 0 and 3"):
        check_symmetry(reacher(), n_trials=0)


def test_checking_keeps_the_seed_record_time_and_controls():
    env = reacher()
    env.reset(seed=7)
    env.step(np.array([0.5, -0.5]))
    data = env.unwrapped.data
    time, ctrl = data.time, data.ctrl.copy()
    check_symmetry(env, n_trials=2)
    assert env.unwrapped.np_random_seed == 7
    assert data.time == time and np.array_equal(data.ctrl, ctrl)


def test_an_inline_declaration_on_the_command_line():
    inline = ("env.symmetry={dim:2,continuous_group:'O(2)',exact_group:C1,observation:["
              "{name:x,rep:sign,index:0},{name:angle,rep:sign,index:1},{name:v,rep:sign,index:2},"
              "{name:w,rep:sign,index:3}],action:[{name:force,rep:sign,index:0}]}")
    resolved = OmegaConf.to_container(config("env=gym", "env.id=InvertedPendulum-v5", inline), resolve=True)
    options = RunOptions.from_config(resolved)
    assert options.env.symmetry["observation"][1] == {"name": "angle", "rep": "sign", "index": 1}
    env = make_gym_env(options.env)
    assert [f.name for f in symmetry_of(env).observation] == ["x", "angle", "v", "w"]
    assert env.action_space.high[0] == 1  # the 3 N box rescaled for the agent, after declare
