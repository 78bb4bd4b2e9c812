"""The run lifecycle both trainers share (train.run, train.runfolder): the same arguments under the same names, their
checks, a renamed option, and a folder of one trainer refused by the other. Needs neither SB3 nor Ray, so it runs in
both venvs of ``make test``; the trainers' own runs are tested in test_train*.py and tests/rllib/."""

import dataclasses

import pytest
import yaml

from train.cli import field_docs, parse_args, parser_for
from train.ppo import SB3_RUN, TrainArgs
from train.rllib import RLLIB_RUN, RLlibArgs
from train.run import Every, RunArgs
from train.runfolder import ConfigMismatchError, prepare_run_folder

TRAINERS = [TrainArgs, RLlibArgs]
SHARED = [f.name for f in dataclasses.fields(RunArgs)]
BAD = [  # (field, value, what the message says)
    ("eval_episodes", 0, "eval_episodes must be >= 1"),
    ("eval_freq", -1, "eval_freq must be >= 0"),
    ("checkpoint_freq", -5, "checkpoint_freq must be >= 0"),
    ("seed", -1, "seed must be >= 0"),
    ("torch_threads", 0, "torch_threads must be an integer >= 1"),
    ("select_after", True, "select_after must be a whole number"),
    ("total_timesteps", 0, "total_timesteps must be >= 1"),
]


@pytest.mark.parametrize("cls", TRAINERS, ids=lambda cls: cls.__name__)
def test_both_trainers_take_the_shared_arguments_as_the_same_options(cls):
    """Every argument of ``RunArgs`` is an option of either command, with its type, its default (the run folder's
    aside) and its help text."""
    own = {f.name: f for f in dataclasses.fields(cls)}
    shared = {f.name: f for f in dataclasses.fields(RunArgs)}
    assert set(shared) <= set(own)
    for name, f in shared.items():
        assert own[name].type == f.type, name
        if name != "out":
            assert own[name].default == f.default and own[name].default_factory == f.default_factory, name
    docs, base_docs = field_docs(cls), field_docs(RunArgs)
    assert all(docs[name] for name in own), "every argument has its help text"
    assert all(docs[name] == base_docs[name] for name in shared if name != "out")
    options = {option for action in parser_for(cls)._actions for option in action.option_strings}
    assert {"--" + name.replace("_", "-") for name in shared} <= options


def test_the_old_env_option_of_train_rllib_names_the_new_one(capsys):
    for argv in (["--env", "leg_env/PlanarLegHop-v4"], ["--env=leg_env/PlanarLegHop-v4"], ["--env"]):
        with pytest.raises(SystemExit) as stop:
            parse_args(RLlibArgs, argv, prog="python -m train.rllib")
        assert stop.value.code == 2 and "--env was renamed --env-id" in capsys.readouterr().err
    assert parse_args(RLlibArgs, ["--env-id", "leg_env/PlanarLegHop-v4"]).env_id == "leg_env/PlanarLegHop-v4"
    assert "--env " not in parser_for(RLlibArgs).format_help()  # not advertised
    with pytest.raises(TypeError, match="'env'"):
        RLlibArgs(env="leg_env/PlanarLegHop-v4")


@pytest.mark.parametrize("cls", TRAINERS, ids=lambda cls: cls.__name__)
@pytest.mark.parametrize("name, value, message", BAD, ids=[b[0] for b in BAD])
def test_a_bad_shared_argument_is_a_value_error_naming_it(cls, name, value, message, capsys):
    with pytest.raises(ValueError, match=message):
        cls(**{name: value})
    if not isinstance(value, bool):  # on the command line: an argument error naming it, nothing created
        with pytest.raises(SystemExit) as stop:
            parse_args(cls, ["--" + name.replace("_", "-"), str(value)])
        assert stop.value.code == 2 and message in capsys.readouterr().err


@pytest.mark.parametrize("cls", TRAINERS, ids=lambda cls: cls.__name__)
def test_an_unknown_keyword_is_a_type_error(cls):
    with pytest.raises(TypeError, match="no_such_argument"):
        cls(no_such_argument=1)


@pytest.mark.sb3
@pytest.mark.parametrize("kind, other", [(SB3_RUN, RLLIB_RUN), (RLLIB_RUN, SB3_RUN)], ids=["ppo-on-rllib", "rllib-on-ppo"])
def test_a_folder_of_the_other_trainer_is_never_resumed_or_replaced_silently(tmp_path, kind, other):
    """A run folder with a checkpoint and the configuration of one trainer is refused by the other, naming the
    trainer; with --overwrite it is emptied of the other's files as well."""
    config = {"env_id": "leg_env/PlanarLegStance-v0", "seed": 0}
    (tmp_path / "checkpoints" / "000000000128").mkdir(parents=True)
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({**config, "trainer": other.trainer}))
    for name in other.policy_files:
        (tmp_path / name).write_text("{}")
    with pytest.raises(ConfigMismatchError, match=r"\(trainer differ\).*--overwrite"):
        prepare_run_folder(tmp_path, {**config, "trainer": kind.trainer}, kind)
    (tmp_path / "notes.txt").write_text("a file of the user's")
    assert prepare_run_folder(tmp_path, {**config, "trainer": kind.trainer}, kind, overwrite=True) is False
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_a_folder_of_the_same_trainer_resumes_when_its_configuration_matches(tmp_path):
    config = {"trainer": "rllib-ppo", **{key: 1 for key in RLLIB_RUN.resume_keys}}
    (tmp_path / "checkpoints" / "000000000128").mkdir(parents=True)
    (tmp_path / "checkpoints" / ".000000000256.x1").mkdir()  # a checkpoint being written when its process was killed
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config))
    assert prepare_run_folder(tmp_path, {**config, "scaling": "changed"}, RLLIB_RUN) is True
    assert [p.name for p in (tmp_path / "checkpoints").iterdir()] == ["000000000128"]
    with pytest.raises(ConfigMismatchError, match=r"\(seed differ\)"):
        prepare_run_folder(tmp_path, {**config, "seed": 2}, RLLIB_RUN)
    with pytest.raises(FileExistsError, match="--no-resume"):
        prepare_run_folder(tmp_path, config, RLLIB_RUN, resume=False)


def test_every_is_due_once_per_multiple_passed():
    every = Every(100, done=150)
    assert [steps for steps in (160, 199, 200, 250, 420, 430, 500) if every.due(steps)] == [200, 420, 500]
    never = Every(0)
    assert not any(never.due(steps) for steps in (0, 1, 10**9))
