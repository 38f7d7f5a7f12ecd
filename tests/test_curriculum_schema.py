"""Curriculum and run-config validation: every bad input gives one clear error."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from myo_sds.curricula.run_config import load_run_config
from myo_sds.curricula.run_settings import LearningRateDecay, PpoWarmup
from myo_sds.curricula.schema import ConfigError, load_curriculum

REPO = Path(__file__).resolve().parents[1]

GOOD_CURRICULUM = """
name: tiny
task: baoding
defaults: {direction: hold, period: static, rsi_probability: 1.0}
stages:
  - name: a
    env: {solved_radius: 0.03}
    advance: {metric: score, threshold: 0.1, window: 5}
  - name: b
    env: {direction: ccw, period: 20}
    advance: {metric: survival, threshold: 0.5, window: 5, min_steps: 100, max_steps: 1000, on_max_steps: stop}
    ppo: {learning_rate: 1e-4, n_steps: 64}
"""


def write(tmp_path: Path, text: str, name: str = "c.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_bundled_and_experiment_curricula_and_configs_load():
    for folder in (REPO, REPO / "experiments"):
        for path in sorted((folder / "curricula").glob("*.yaml")):
            curriculum = load_curriculum(path)
            assert curriculum.stages, path
        for path in sorted((folder / "configs").glob("*.yaml")):
            config = load_run_config(path)
            assert config.curriculum.stages, path


def test_a_config_inherits_its_base_and_overrides_key_by_key(tmp_path):
    (tmp_path / "product").mkdir()
    (tmp_path / "exp").mkdir()
    write(tmp_path / "product", GOOD_CURRICULUM, "cur.yaml")
    write(tmp_path / "product", "curriculum: cur.yaml\nseed: 3\nn_envs: 2\n"
          "ppo: {learning_rate: 3.0e-4, n_steps: 64, batch_size: 64, n_epochs: 10}\n", "base.yaml")
    child = write(tmp_path / "exp", "base: ../product/base.yaml\nppo: {n_epochs: 5}\nseed: 7\n", "child.yaml")
    config = load_run_config(child)
    # The child's values win; the rest of ppo stays the base's; the base's curriculum path is
    # read relative to the base.
    assert (config.seed, config.n_envs, config.ppo.n_epochs, config.ppo.learning_rate) == (7, 2, 5, 3.0e-4)
    assert config.curriculum_path == (tmp_path / "product" / "cur.yaml").resolve()
    assert "base" not in config.source and config.source["ppo"]["n_steps"] == 64
    # A grandchild, and an error in a value a base wrote names that base's file.
    write(tmp_path / "exp", "base: child.yaml\nn_envs: 4\n", "grandchild.yaml")
    assert load_run_config(tmp_path / "exp" / "grandchild.yaml").ppo.n_epochs == 5
    write(tmp_path / "product", "curriculum: cur.yaml\nppo: {gamma: 3, n_steps: 64, batch_size: 64}\n", "bad.yaml")
    write(tmp_path / "exp", "base: ../product/bad.yaml\nseed: 1\n", "on_bad.yaml")
    with pytest.raises(ConfigError, match=re.escape(f"{(tmp_path / 'product' / 'bad.yaml').resolve()}: ppo.gamma: must be <= 1")):
        load_run_config(tmp_path / "exp" / "on_bad.yaml")
    write(tmp_path / "exp", "base: loop_b.yaml\n", "loop_a.yaml")
    write(tmp_path / "exp", "base: loop_a.yaml\n", "loop_b.yaml")
    with pytest.raises(ConfigError, match="a cycle of bases"):
        load_run_config(tmp_path / "exp" / "loop_a.yaml")
    write(tmp_path / "exp", "base: nowhere.yaml\n", "orphan.yaml")
    with pytest.raises(ConfigError, match="base: run config file not found"):
        load_run_config(tmp_path / "exp" / "orphan.yaml")


def test_a_curriculum_inherits_its_base_defaults_key_by_key_and_its_stages_unless_written(tmp_path):
    write(tmp_path, GOOD_CURRICULUM.replace("rsi_probability: 1.0}", "rsi_probability: 1.0, "
                                            "reward_weights: {pos_dist_1: 1.0, solved: 5.0}}"), "tiny.yaml")
    variant = load_curriculum(write(tmp_path, "base: tiny.yaml\ndefaults: {reward_weights: {solved: 2.0}}\n",
                                    "tiny_variant.yaml"))
    base = load_curriculum(tmp_path / "tiny.yaml")
    # Named by its own file; the base's stages, each with the one weight changed.
    assert (variant.name, base.name) == ("tiny_variant", "tiny")
    assert [s.name for s in variant.stages] == ["a", "b"] and variant.stages[1].ppo == base.stages[1].ppo
    for mine, theirs in zip(variant.stages, base.stages):
        assert dict(mine.distribution.reward_weights) == {**theirs.distribution.reward_weights, "solved": 2.0}
        assert dict(theirs.distribution.reward_weights)["solved"] == 5.0
        assert mine.distribution.solved_radius == theirs.distribution.solved_radius
    # Stages written in the variant replace the base's list when it says so; a bad value the base
    # wrote names the base.
    one = load_curriculum(write(tmp_path, "base: tiny.yaml\nreplace_stages: true\nstages:\n  - name: only\n",
                                "one_stage.yaml"))
    assert [s.name for s in one.stages] == ["only"] and one.task == "baoding"
    write(tmp_path, GOOD_CURRICULUM.replace("solved_radius: 0.03", "solved_radius: -1"), "bad_base.yaml")
    with pytest.raises(ConfigError, match=re.escape(f"{(tmp_path / 'bad_base.yaml').resolve()}: stage 1")):
        load_curriculum(write(tmp_path, "base: bad_base.yaml\nname: on_bad\n", "on_bad.yaml"))


def test_good_curriculum_is_parsed_with_defaults_merged(tmp_path):
    curriculum = load_curriculum(write(tmp_path, GOOD_CURRICULUM))
    a, b = curriculum.stages
    assert a.env == {"direction": "hold", "period": "static", "rsi_probability": 1.0, "solved_radius": 0.03}
    assert b.env["direction"] == "ccw" and b.env["rsi_probability"] == 1.0
    assert b.advance.metric == "survival" and b.advance.on_max_steps == "stop"
    assert b.ppo.learning_rate == 1e-4 and b.ppo.n_steps == 64  # "1e-4" read as a number


@pytest.mark.parametrize("old,new,expected", [
    ("    advance: {metric: score, threshold: 0.1, window: 5}",
     "    advance: {metric: score, threshold: 1.5, window: 5}",
     "stage 1 (a) advance.threshold: must be in [0, 1] for score"),
    ("    advance: {metric: score, threshold: 0.1, window: 5}",
     "    advance: {metric: score, threshold: 0.1, windw: 5}",
     "stage 1 (a) advance.windw: unknown key (did you mean 'window'?); allowed: metric, threshold, window"),
    ("    advance: {metric: score, threshold: 0.1, window: 5}",
     "    advance: {metric: succes, threshold: 0.1, window: 5}",
     "stage 1 (a) advance.metric: 'succes' is not one of score, survival"),
    ("    advance: {metric: score, threshold: 0.1, window: 5}",
     "    advance: {metric: score, threshold: high, window: 5}",
     "stage 1 (a) advance.threshold: expected a number, got 'high'"),
    ("    advance: {metric: score, threshold: 0.1, window: 5}",
     "    advance: {metric: score, threshold: 0.1, window: 2.5}",
     "stage 1 (a) advance.window: expected an integer"),
    ("    env: {solved_radius: 0.03}", "    env: {solved_radus: 0.03}",
     "stage 1 (a) env.solved_radus: unknown key (did you mean 'solved_radius'?)"),
    ("    env: {solved_radius: 0.03}", "    env: {period: [20, 10]}",
     "stage 1 (a) env: period: range [20.0, 10.0] is reversed"),
    ("    env: {solved_radius: 0.03}", "    env: {direction: up}",
     "stage 1 (a) env: direction: 'up' is not one of hold, cw, ccw, random"),
    ("task: baoding", "task: juggling", "task: 'juggling' is not one of baoding"),
    ("  - name: b", "  - name: a", "stage 2 name: duplicate stage name 'a'"),
    ("    ppo: {learning_rate: 1e-4, n_steps: 64}", "    ppo: {lr: 1e-4}",
     "stage 2 (b) ppo.lr: unknown key; allowed: learning_rate, n_steps, batch_size, n_epochs, clip_range, ent_coef, "
     "target_kl"),
    ("max_steps: 1000,", "max_steps: 50,", "stage 2 (b) advance.max_steps: 50 is below min_steps 100"),
    ("learning_rate: 1e-4,", "learning_rate: {start: 1e-3, end: 1e-4},",
     "stage 2 (b) ppo.learning_rate.steps: missing: env steps from start to end"),
    ("learning_rate: 1e-4,", "learning_rate: {start: 1e-3, end: 1e-4, stesp: 10},",
     "stage 2 (b) ppo.learning_rate.stesp: unknown key (did you mean 'steps'?); allowed: start, end, steps"),
    ("learning_rate: 1e-4,", "learning_rate: {start: 1e-3, end: 0, steps: 10},",
     "stage 2 (b) ppo.learning_rate.end: must be > 0, got 0"),
])
def test_bad_curriculum_names_file_key_and_allowed(tmp_path, old, new, expected):
    assert old in GOOD_CURRICULUM
    path = write(tmp_path, GOOD_CURRICULUM.replace(old, new))
    with pytest.raises(ConfigError) as error:
        load_curriculum(path)
    message = str(error.value)
    assert message.startswith(f"{path}: ")
    assert expected in message


def test_missing_and_invalid_files(tmp_path):
    with pytest.raises(ConfigError, match="curriculum file not found"):
        load_curriculum(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_curriculum(write(tmp_path, "stages: [a, b\n"))
    with pytest.raises(ConfigError, match="stages: expected a non-empty list"):
        load_curriculum(write(tmp_path, "name: x\nstages: []\n"))
    with pytest.raises(ConfigError, match="the curriculum file is empty"):
        load_curriculum(write(tmp_path, ""))


def test_run_config_errors(tmp_path):
    write(tmp_path, GOOD_CURRICULUM, "cur.yaml")
    good = "curriculum: cur.yaml\nseed: 3\nn_envs: 2\nppo: {n_steps: 64, batch_size: 64}\n"
    config = load_run_config(write(tmp_path, good, "run.yaml"))
    assert config.seed == 3 and config.n_envs == 2 and config.ppo.learning_rate == 2.56e-5
    cases = {
        "curriculum: missing.yaml\n": "curriculum: curriculum file not found",
        good + "n_env: 4\n": "n_env: unknown key (did you mean 'n_envs'?)",
        good + "vec_env: threads\n": "vec_env: 'threads' is not one of thread, dummy, subproc",
        good + "policy: {activation: swish}\n": "policy.activation: 'swish' is not one of relu",
        good + "policy: {net_arch: 256}\n": "policy.net_arch: expected a list of layer sizes ([] for none)",
        good + "normalize: {observations: yes please}\n": "normalize.observations: expected true or false",
        "seed: 1\n": "curriculum: missing",
        good.replace("batch_size: 64", "batch_size: 512"): "ppo.batch_size: 512 exceeds the rollout size",
        good + "ppo: {gamma: 1.5}\n": "ppo.gamma: must be <= 1",
        good + "policy: {action_mean_bound: -1}\n": "policy.action_mean_bound: must be >= 0",
        good + "policy: {action_mean_bound: 1.5, fast_lstm_update: false}\n":
            "policy.action_mean_bound: needs policy.fast_lstm_update: true",
        good + "policy: {action_head_lr_scale: 0}\n": "policy.action_head_lr_scale: must be > 0",
        good + "policy: {action_head_lr_scale: 0.1, fast_lstm_update: false}\n":
            "policy.action_head_lr_scale: needs policy.fast_lstm_update: true",
    }
    for text, expected in cases.items():
        path = write(tmp_path, text, "bad.yaml")
        with pytest.raises(ConfigError) as error:
            load_run_config(path)
        assert str(error.value).startswith(f"{path}: ") and expected in str(error.value), text


def test_stage_batch_size_is_checked_against_the_run(tmp_path):
    write(tmp_path, GOOD_CURRICULUM.replace("n_steps: 64}", "n_steps: 64, batch_size: 256}"), "cur.yaml")
    path = write(tmp_path, "curriculum: cur.yaml\nn_envs: 2\nppo: {n_steps: 64, batch_size: 64}\n", "run.yaml")
    with pytest.raises(ConfigError, match=r"stage 2 \(b\) ppo: batch_size 256 exceeds the rollout size .* 64 x 2"):
        load_run_config(path)
    assert load_run_config(path, ("n_envs=4",)).n_envs == 4
    # A --set that shrinks the rollout below the file's batch size is named beside it.
    with pytest.raises(ConfigError, match=r"run.yaml: ppo.batch_size: 64 exceeds the rollout size n_steps x n_envs "
                                          r"= 16 x 2 = 32 \(n_steps from --set ppo.n_steps=16, n_envs from .*run.yaml\)"):
        load_run_config(path, ("ppo.n_steps=16",))


def test_set_overrides_are_checked_against_the_schema(tmp_path):
    write(tmp_path, GOOD_CURRICULUM, "cur.yaml")
    path = write(tmp_path, "curriculum: cur.yaml\nppo: {n_steps: 64, batch_size: 64}\n", "run.yaml")
    config = load_run_config(path, ("ppo.learning_rate=3e-4", "n_envs=2", "policy.net_arch=[32, 32]"))
    assert config.ppo.learning_rate == 3e-4 and config.n_envs == 2 and config.policy.net_arch == (32, 32)
    # An error in an override names the override, not the file (which has no such key).
    with pytest.raises(ConfigError) as error:
        load_run_config(path, ("ppo.lerning_rate=1e-4",))
    assert str(error.value) == ("--set ppo.lerning_rate=1e-4: ppo.lerning_rate: unknown key (did you mean "
                                "'learning_rate'?); allowed: learning_rate, n_steps, batch_size, n_epochs, gamma, "
                                "gae_lambda, clip_range, ent_coef, vf_coef, max_grad_norm, target_kl, sequence_length, warmup")
    with pytest.raises(ConfigError, match=r"^--set n_env=2: n_env: unknown key \(did you mean 'n_envs'\?\)"):
        load_run_config(path, ("n_env=2",))
    with pytest.raises(ConfigError, match=r"^--set ppo.gamma=2: ppo.gamma: must be <= 1, got 2"):
        load_run_config(path, ("ppo.gamma=2",))
    with pytest.raises(ConfigError, match=r"^--set ppo.n_steps=6.5: ppo.n_steps: expected an integer"):
        load_run_config(path, ("ppo.n_steps=6.5",))
    with pytest.raises(ConfigError, match="expected key=value"):
        load_run_config(path, ("ppo.learning_rate",))
    # A bad value in the file is still the file's, even when another key is overridden.
    bad_file = write(tmp_path, "curriculum: cur.yaml\nppo: {n_steps: 64, batch_size: 64, gamma: 3}\n", "bad.yaml")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(bad_file))}: ppo.gamma: must be <= 1"):
        load_run_config(bad_file, ("ppo.learning_rate=3e-4",))


def test_learning_rate_decay_is_read_from_configs_stages_and_overrides(tmp_path):
    decay = "{start: 1e-3, end: 1e-5, steps: 1000}"
    write(tmp_path, GOOD_CURRICULUM.replace("learning_rate: 1e-4,", f"learning_rate: {decay},"), "cur.yaml")
    path = write(tmp_path, f"curriculum: cur.yaml\nppo: {{learning_rate: {decay}, n_steps: 64, batch_size: 64}}\n",
                 "run.yaml")
    config = load_run_config(path)
    assert config.ppo.learning_rate == LearningRateDecay(start=1e-3, end=1e-5, steps=1000)
    assert config.curriculum.stages[1].ppo.learning_rate == LearningRateDecay(1e-3, 1e-5, 1000)
    overridden = load_run_config(path, ("ppo.learning_rate={start: 2e-3, end: 2e-4, steps: 50}",))
    assert overridden.ppo.learning_rate == LearningRateDecay(2e-3, 2e-4, 50)
    assert load_run_config(path, ("ppo.learning_rate=3e-4",)).ppo.learning_rate == 3e-4


def test_learning_rate_decay_falls_log_linearly_then_holds():
    decay = LearningRateDecay(start=1e-3, end=1e-5, steps=1000)
    assert decay.at(0) == pytest.approx(1e-3)
    assert decay.at(500) == pytest.approx(1e-4)  # halfway in steps: the geometric mean
    assert decay.at(250) == pytest.approx(1e-3 * 10 ** -0.5)
    assert decay.at(1000) == pytest.approx(1e-5) and decay.at(10**9) == pytest.approx(1e-5)


def test_ppo_warmup_is_read_and_checked(tmp_path):
    write(tmp_path, GOOD_CURRICULUM, "cur.yaml")
    base = "curriculum: cur.yaml\nn_envs: 2\nppo: {n_steps: 64, batch_size: 64, warmup: WARMUP}\n"
    config = load_run_config(write(tmp_path, base.replace("WARMUP", "{steps: 5000, n_epochs: 20}"), "run.yaml"))
    assert config.ppo.warmup == PpoWarmup(steps=5000, n_steps=None, batch_size=None, n_epochs=20)
    assert config.ppo.warmup.active(4999) and not config.ppo.warmup.active(5000)
    assert load_run_config(write(tmp_path, base.replace(", warmup: WARMUP", ""), "plain.yaml")).ppo.warmup.steps == 0
    cases = {
        "{batch_size: 32}": "ppo.warmup: a warm-up needs steps",
        "{steps: 100, epochs: 3}": "ppo.warmup.epochs: unknown key (did you mean 'n_epochs'?); allowed: steps, n_steps, batch_size, n_epochs",
        "{steps: 100, batch_size: 256}": "ppo.warmup.batch_size: 256 exceeds the warm-up's rollout size n_steps x n_envs = 128",
        "{steps: 100, n_steps: 16}": "ppo.warmup.batch_size: 64 exceeds the warm-up's rollout size n_steps x n_envs = 32",
        "{steps: 100, n_epochs: 0}": "ppo.warmup.n_epochs: must be >= 1",
        "{steps: -5}": "ppo.warmup.steps: must be >= 0",
    }
    for warmup, expected in cases.items():
        path = write(tmp_path, base.replace("WARMUP", warmup), "bad.yaml")
        with pytest.raises(ConfigError) as error:
            load_run_config(path)
        assert str(error.value).startswith(f"{path}: ") and expected in str(error.value), warmup
    overridden = load_run_config(write(tmp_path, base.replace(", warmup: WARMUP", ""), "plain.yaml"),
                                 ("ppo.warmup.steps=300", "ppo.warmup.batch_size=32"))
    assert overridden.ppo.warmup == PpoWarmup(steps=300, batch_size=32)


def test_a_stage_changes_epochs_and_target_kl_until_a_later_stage_does(tmp_path):
    from myo_sds.curricula.schedule import ppo_settings_at

    curriculum = GOOD_CURRICULUM.replace("ppo: {learning_rate: 1e-4, n_steps: 64}",
                                         "ppo: {learning_rate: 1e-4, n_steps: 64, n_epochs: 5, target_kl: 0.2}")
    write(tmp_path, curriculum, "cur.yaml")
    config = load_run_config(write(tmp_path, "curriculum: cur.yaml\nppo: {n_steps: 64, batch_size: 64, n_epochs: 10}\n",
                                   "run.yaml"))
    first = ppo_settings_at(config, 0, [0], 10)
    second = ppo_settings_at(config, 1, [0, 500], 600)
    assert (first.n_epochs, first.target_kl) == (10, None)
    assert (second.n_epochs, second.target_kl) == (5, 0.2)


def test_every_setting_is_declared_one_way_with_a_parser_and_a_meaning():
    from dataclasses import fields

    from myo_sds.curricula import run_config, run_settings, schema
    from myo_sds.envs.baoding_task import BaodingKnobs
    from myo_sds.envs.die_task import DieKnobs
    from myo_sds.envs.knobs import RecordedStart

    declared = (run_settings.RunSettings, run_settings.PolicyConfig, run_settings.PpoConfig,
                run_settings.NormalizeConfig, run_settings.RolloutConfig, schema.AdvanceRule, schema.StageEvaluation,
                schema.PpoOverrides, schema.StageEndProbe, run_settings.LearningRateDecay, run_settings.PpoWarmup,
                RecordedStart, BaodingKnobs, DieKnobs)
    for cls in declared:
        for field in fields(cls):
            assert callable(field.metadata.get("parse")), f"{cls.__name__}.{field.name}"
            assert field.metadata.get("help"), f"{cls.__name__}.{field.name}"
    # The run config's top level is read through them too: a bad value names the file and key.
    assert set(run_config.RUN_KEYS) >= {f.name for f in fields(run_settings.RunSettings)}


def test_a_variant_changes_one_stage_by_name_and_keeps_the_rest(tmp_path):
    """Three lines change one threshold; every other setting of that stage and the other stages stay."""
    write(tmp_path, GOOD_CURRICULUM, "base.yaml")
    variant = write(tmp_path, "base: base.yaml\nstages:\n  b: {advance: {threshold: 0.7}}\n", "variant.yaml")
    base, changed = load_curriculum(tmp_path / "base.yaml"), load_curriculum(variant)
    assert [s.name for s in changed.stages] == ["a", "b"] and changed.stages[0] == base.stages[0]
    b, base_b = changed.stages[1], base.stages[1]
    assert b.advance.threshold == 0.7 and b.advance.metric == "survival" and b.advance.max_steps == 1000
    assert (b.env, b.ppo) == (base_b.env, base_b.ppo)
    assert changed.origins["stages.b.advance.threshold"] == str(variant.resolve())
    assert changed.origins["stages.b.advance.window"] == str((tmp_path / "base.yaml").resolve())
    # A run folder's copy of the variant is self-contained and reads back as the same curriculum.
    copy = write(tmp_path, changed.file_text(), "copy.yaml")
    assert load_curriculum(copy).stages == changed.stages
    # Add (placed after or before a named stage), move, remove, each said explicitly.
    more = write(tmp_path, "base: base.yaml\nstages:\n"
                 "  c: {after: a, env: {direction: cw, period: 30}, advance: {threshold: 0.3}}\n"
                 "  a: {after: b}\n", "more.yaml")
    assert [s.name for s in load_curriculum(more).stages] == ["c", "b", "a"]
    fewer = write(tmp_path, "base: base.yaml\nstages:\n  a: null\n", "fewer.yaml")
    assert [s.name for s in load_curriculum(fewer).stages] == ["b"]
    # A list is the whole stage order: one that leaves out base stages names them and says how to
    # keep them, unless it says it replaces the order; a listed stage keeps its other settings.
    listed = write(tmp_path, "base: base.yaml\nstages:\n  - {name: b, advance: {threshold: 0.6}}\n", "listed.yaml")
    with pytest.raises(ConfigError, match=r"listed.yaml: stages: this list leaves out a of its base .*base.yaml .*"
                                          r"write a mapping \(stages: \{b: \{advance: \.\.\.\}\}\), or add "
                                          r"replace_stages: true"):
        load_curriculum(listed)
    listed.write_text("replace_stages: true\n" + listed.read_text())
    (only,) = load_curriculum(listed).stages
    assert only.advance.threshold == 0.6 and only.advance.max_steps == 1000 and only.ppo == base_b.ppo
    whole = write(tmp_path, "base: base.yaml\nstages:\n  - {name: b}\n  - {name: a}\n", "whole.yaml")
    assert [s.name for s in load_curriculum(whole).stages] == ["b", "a"]  # every stage listed: a new order
    with pytest.raises(ConfigError, match="replace_stages: only a variant"):
        load_curriculum(write(tmp_path, "replace_stages: true\n" + GOOD_CURRICULUM, "nobase.yaml"))
    for text, message in (("  z: {advance: {threshold: 0.5}}", "stages.z: no base stage of that name; to add one"),
                          ("  z: null", "stages.z: null removes a stage, but the base has none"),
                          ("  c: {after: q, advance: {threshold: 0.5}}", "stages.c.after: no stage named 'q'"),
                          ("  b: {advance: {threshold: 2}}", "stage 2 \\(b\\) advance.threshold: must be in")):
        bad = write(tmp_path, f"base: base.yaml\nstages:\n{text}\n", "bad.yaml")
        with pytest.raises(ConfigError, match=message):
            load_curriculum(bad)


def test_set_reaches_curriculum_values_and_null_turns_an_optional_setting_off(tmp_path):
    from myo_sds.curricula.schedule import ppo_settings_at

    write(tmp_path, GOOD_CURRICULUM.replace("ppo: {learning_rate: 1e-4, n_steps: 64}",
                                            "ppo: {learning_rate: 1e-4, n_steps: 64, target_kl: 0.05}")
          + "  - name: c\n    env: {direction: cw, period: 20}\n    ppo: {target_kl: null}\n", "cur.yaml")
    config_file = write(tmp_path, "curriculum: cur.yaml\nppo: {target_kl: 0.1}\n", "run.yaml")
    config = load_run_config(config_file, ("stages.b.advance.threshold=0.8", "defaults.solved_radius=0.02"))
    assert config.curriculum.stages[1].advance.threshold == 0.8
    assert config.curriculum.stages[0].distribution.solved_radius == 0.03  # the stage's own value wins
    assert config.curriculum.stages[1].distribution.solved_radius == 0.02
    assert config.curriculum.origins["stages.b.advance.threshold"] == "--set stages.b.advance.threshold=0.8"
    assert "threshold: 0.8" in config.curriculum.file_text()
    # target_kl: the run's 0.1, stage b's 0.05, stage c's null switches it off.
    assert [ppo_settings_at(config, i, [0, 10, 20], 30).target_kl for i in range(3)] == [0.1, 0.05, None]
    for assignment, message in (("stages.q.advance.threshold=0.5", "no stage named 'q'; stages: a, b, c"),
                                ("stages.b.advance.threshold=2", "--set stages.b.advance.threshold=2: stage 2 \\(b\\) "
                                                                 "advance.threshold: must be in \\[0, 1\\]"),
                                ("stages.b.ppo.n_steps=null", "ppo.n_steps: expected an integer, got None"),
                                ("stagez.b.x=1", "stagez: unknown key \\(did you mean 'stages'\\?\\)")):
        with pytest.raises(ConfigError, match=message):
            load_run_config(config_file, (assignment,))


def test_a_setting_declared_once_is_read_everywhere_it_applies():
    """A settings class and the stage overrides made from it share each field's one declaration:
    a new field is read, checked and described in both without another line."""
    from dataclasses import dataclass

    from myo_sds.envs.declare import UNSET, describe, integer, overrides_of, parse_settings, setting

    @dataclass(frozen=True)
    class Settings:
        n_steps: int = setting(128, parse=integer(low=1), help="rollout steps per env")
        warm_rollouts: int = setting(0, parse=integer(low=0), help="rollouts before the first update")  # the new one

    Overrides = overrides_of(Settings, ("n_steps", "warm_rollouts"), "Overrides", "a stage's changes")
    assert parse_settings("ppo", {"warm_rollouts": 3}, Settings).warm_rollouts == 3
    assert parse_settings("stage 2 (b) ppo", {"warm_rollouts": 2}, Overrides).as_dict() == {"warm_rollouts": 2}
    assert Overrides().warm_rollouts is UNSET and describe(Overrides) == describe(Settings)
    for cls, path in ((Settings, "ppo"), (Overrides, "stage 2 (b) ppo")):
        with pytest.raises(ValueError, match=f"{re.escape(path)}.warm_rollouts: must be >= 0, got -1"):
            parse_settings(path, {"warm_rollouts": -1}, cls)
    # The real ones: a stage's ppo is the run config's ppo declarations, unset until written.
    from dataclasses import fields

    from myo_sds.curricula.run_settings import STAGE_PPO_SETTINGS, PpoConfig
    from myo_sds.curricula.schema import PpoOverrides

    declared = {f.name: f.metadata for f in fields(PpoConfig)}
    assert [f.name for f in fields(PpoOverrides)] == list(STAGE_PPO_SETTINGS)
    assert all(f.metadata["parse"] is declared[f.name]["parse"] for f in fields(PpoOverrides))


def test_print_config_shows_every_value_and_where_it_came_from(tmp_path, capsys, monkeypatch):
    from myo_sds.cli.train import main

    write(tmp_path, GOOD_CURRICULUM.replace("defaults: {direction: hold, period: static, rsi_probability: 1.0}",
                                            "defaults: {direction: hold, period: static, rsi_probability: 1.0, "
                                            "preset: p1_2022, reward_weights: {alive: 1.0, solved: 5.0}}"), "base.yaml")
    write(tmp_path, "base: base.yaml\ndefaults: {reward_weights: {solved: 2.0}}\n"
                    "stages:\n  b: {advance: {threshold: 0.7}}\n", "variant.yaml")
    write(tmp_path, "curriculum: variant.yaml\nn_envs: 2\n", "run.yaml")
    monkeypatch.chdir(tmp_path)
    assert main(["--config", "run.yaml", "--set", "stages.a.env.solved_radius=0.02", "--print-config"]) == 0
    rows = {line.split()[0]: line.split()[1:] for line in capsys.readouterr().out.splitlines()[1:]}
    assert rows["n_envs"] == ["2", "run.yaml"] and rows["seed"] == ["0", "default"]
    assert rows["stages.b.advance.threshold"] == ["0.7", "variant.yaml"]
    assert rows["stages.b.advance.window"] == ["5", "base.yaml"]
    assert rows["stages.a.env.solved_radius"] == ["0.02", "--set", "stages.a.env.solved_radius=0.02"]
    assert rows["stages.b.env.direction"] == ["ccw", "base.yaml"]
    assert rows["stages.a.env.direction"] == ["hold", "defaults:", "base.yaml"]
    assert rows["stages.a.env.start_angle"] == ["on_balls", "preset", "p1_2022"]
    assert rows["stages.a.env.drop_height"] == ["1.25", "default"]
    # A mapping merged from two files names both.
    assert rows["stages.a.env.reward_weights"][-4:] == ["defaults:", "base.yaml", "+", "variant.yaml"]
    assert rows["stages.b.ppo.n_steps"] == ["64", "base.yaml"] and "stages.a.ppo.n_steps" not in rows
    assert not (tmp_path / "runs").exists()  # nothing trained, no run folder


def test_a_bad_default_is_named_where_the_default_was_set_not_where_the_stage_was(tmp_path):
    """A variant that writes only ``defaults`` is the file to blame for a bad default every
    inherited stage reads; a stage's own bad value still names the stage."""
    write(tmp_path, GOOD_CURRICULUM.replace("rsi_probability: 1.0", "rsi_probability: 1.0, reward_weights: {alive: 1.0}"),
          "base.yaml")
    variant = write(tmp_path, "base: base.yaml\ndefaults: {reward_weights: {alive: null}}\n", "variant.yaml")
    with pytest.raises(ConfigError) as caught:
        load_curriculum(variant)
    assert str(caught.value).startswith(f"{variant}: defaults.reward_weights.alive: expected a number, got None "
                                        "(in stage 1 (a))")
    own = write(tmp_path, "base: base.yaml\nstages:\n  a: {env: {rsi_probability: 2}}\n", "own.yaml")
    with pytest.raises(ConfigError, match=r"own.yaml: stage 1 \(a\) env: rsi_probability"):
        load_curriculum(own)


def test_a_curriculum_file_runs_with_the_bundled_config_of_what_it_is_based_on(tmp_path, monkeypatch):
    """``--config my_curriculum.yaml``: a variant of a bundled curriculum runs with that
    curriculum's bundled run config; paths in a file are relative to it, a --set path to the
    working folder; a curriculum nothing follows says how to run it."""
    mine = tmp_path / "elsewhere" / "mine.yaml"
    mine.parent.mkdir()
    mine.write_text(f"base: {os.path.relpath(REPO / 'curricula' / 'quickstart.yaml', mine.parent)}\n"
                    "stages:\n  p1-noise: {advance: {threshold: 0.07}}\n")
    monkeypatch.chdir(tmp_path)
    config = load_run_config(Path("elsewhere/mine.yaml"))
    quickstart = load_run_config(REPO / "configs" / "quickstart.yaml")
    assert config.curriculum_path == mine.resolve() and config.init_from == quickstart.init_from
    assert (config.total_steps, config.ppo) == (quickstart.total_steps, quickstart.ppo)
    assert [(s.name, s.advance.threshold) for s in config.curriculum.stages] == [("p1-noise", 0.07), ("p1-noise-better", 0.3)]
    # --set curriculum= is a path from the working folder, not from the config's folder.
    config = load_run_config(REPO / "configs" / "quickstart.yaml", ("curriculum=elsewhere/mine.yaml",))
    assert config.curriculum_path == mine.resolve()
    alone = write(tmp_path, GOOD_CURRICULUM, "alone.yaml")
    with pytest.raises(ConfigError, match=r"alone.yaml: a curriculum that no bundled run config follows .*"
                                          r"--config baoding_sds --set curriculum=.*alone.yaml"):
        load_run_config(alone)
