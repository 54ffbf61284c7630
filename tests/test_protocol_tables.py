"""The protocols' tables and settings: paired comparisons, the oracle check, the markdown, the nested transfer settings
and the cache's fingerprint."""

from __future__ import annotations

import pytest
import yaml
from test_protocols import protocol_args, protocol_yaml

from mesh2tex.cli import main
from mesh2tex.evaluation.paired import compare_to_full, oracle_check, paired_query_tests, paired_query_wins
from mesh2tex.evaluation.report import protocols_markdown
from mesh2tex.evaluation.world import other_shape_name


def test_comparison_counts_wins_by_each_metrics_direction():
    methods = {
        "full": {"query": {"seen part_delta_e": 5.0, "seen lowpass_psnr": 20.0, "unseen swd": 30.0, "seen psnr": 18.0}},
        "flat_colour": {
            "query": {"seen part_delta_e": 9.0, "seen lowpass_psnr": 21.0, "unseen swd": 30.0, "seen psnr": 17.0}
        },
    }
    c = compare_to_full(methods)["flat_colour"]
    assert c["full_better"] == {
        "seen part_delta_e": True,
        "seen lowpass_psnr": False,
        "unseen swd": False,
        "seen psnr": True,
    }
    assert (c["wins"], c["ties"], c["metrics"]) == (2, 1, 4)


def test_oracle_check_names_the_columns_the_ground_truth_loses():
    methods = {
        "oracle": {"query": {"seen part_delta_e": 1.0, "seen psnr": 30.0}},
        "flat_colour": {"query": {"seen part_delta_e": 9.0, "seen psnr": 31.0}},
    }
    assert oracle_check(methods) == ["seen psnr"]
    methods["flat_colour"]["query"]["seen psnr"] = 20.0
    assert oracle_check(methods) == []


def test_paired_query_wins_compare_the_same_queries():
    full = [
        {"query": "a", "seen psnr": 20.0, "seen part_delta_e": 0.2},
        {"query": "b", "seen psnr": 18.0, "seen part_delta_e": 0.5},
    ]
    other = [
        {"query": "b", "seen psnr": 17.0, "seen part_delta_e": 0.5},
        {"query": "a", "seen psnr": 21.0, "seen part_delta_e": 0.3},
    ]
    assert paired_query_wins(full, other) == {"seen psnr": [1, 2], "seen part_delta_e": [1, 2]}


def test_paired_tests_separate_a_consistent_advantage_from_noise():
    names = [f"q{i}" for i in range(8)]
    other = [{"query": n, "seen psnr": 15.0 + i, "seen part_delta_e": 0.5} for i, n in enumerate(names)]
    # Better on every query (higher PSNR, lower colour error): the smallest exact p of 8 pairs, 2/256.
    better = [{"query": n, "seen psnr": 15.5 + i + 0.1 * i, "seen part_delta_e": 0.4} for i, n in enumerate(names)]
    tests = paired_query_tests(better, other)
    assert tests["seen psnr"]["p_wilcoxon"] < 0.01 and tests["seen psnr"]["mean_difference"] > 0
    assert (
        tests["seen part_delta_e"]["p_wilcoxon"] < 0.01
        and abs(tests["seen part_delta_e"]["mean_difference"] - 0.1) < 1e-9
    )
    # Wins and losses of matched sizes: no evidence either way.
    mixed = [
        {"query": n, "seen psnr": 15.0 + i + (1.0 if i % 2 else -1.0), "seen part_delta_e": 0.5}
        for i, n in enumerate(names)
    ]
    tests = paired_query_tests(mixed, other)
    assert tests["seen psnr"]["p_wilcoxon"] > 0.5 and tests["seen psnr"]["mean_difference"] == 0
    assert tests["seen part_delta_e"]["p_wilcoxon"] is None  # every difference is 0


def test_other_shape_is_never_the_query_shape():
    assert other_shape_name("b", ["a", "b", "c"]) == "c"
    assert other_shape_name("c", ["a", "b", "c"]) == "a"
    with pytest.raises(Exception, match="second prepared shape"):
        other_shape_name("a", ["a"])


def test_markdown_marks_the_best_value_and_says_which_way_is_better():
    rows = lambda value: [{"query": "q", "seen part_delta_e": value}]
    result = {
        "settings": {"latent_iters": 1, "refine_iters": 1, "resolution": 64, "patch_size": 32},
        "world": "w",
        "gan": "g",
        "counts": {"queries": 1},
        "features": "f",
        "comparison": {},
        "protocols": {
            "known_pose": {
                "queries": [{"azimuth_error": 0.0, "elevation_error": 0.0}],
                "methods": {
                    "oracle": {"query": {"seen part_delta_e": 0.5}, "per_query": rows(0.5), "seconds": 0.0},
                    "flat_colour": {"query": {"seen part_delta_e": 9.0}, "per_query": rows(9.0), "seconds": 0.0},
                    "full": {"query": {"seen part_delta_e": 4.0}, "per_query": rows(4.0), "seconds": 1.0},
                    "no_noc": {"query": {"seen part_delta_e": 5.0}, "per_query": rows(5.0), "seconds": 1.0},
                },
            }
        },
    }
    table = protocols_markdown(result)
    assert "| method | seen per-part ΔE ↓ | seconds |" in table
    assert "| full method | **4** | 1 |" in table and "| w/o NOC | 5 | 1 |" in table
    assert "| ground-truth texture (oracle) | 0.5 | 0 |" in table and "The oracle wins every column." in table
    assert "seen per-part ΔE 0.44 of the flat colour's, lower on 1 of 1 queries" in table


def test_the_report_gives_the_pose_error_up_to_the_shapes_symmetries_beside_the_plain_one():
    """A bench found half a turn round is 180 degrees off plainly and right up to its symmetry: the report
    says both, so a mean dragged up by symmetric shapes is not read as a pose network that fails."""
    from mesh2tex.evaluation.report import _pose_lines

    queries = [
        {"azimuth_error": 179.0, "elevation_error": 2.0, "symmetric_azimuth_error": 1.0, "symmetries": 2},
        {"azimuth_error": 3.0, "elevation_error": 2.0, "symmetric_azimuth_error": 3.0, "symmetries": 1},
        {"azimuth_error": 40.0, "elevation_error": 2.0, "symmetric_azimuth_error": 40.0, "symmetries": 1},
    ]
    line = _pose_lines(queries)[1]
    assert "mean azimuth error 74.0 deg" in line
    assert "(1 of 3 photos show a shape that looks the same turned): mean 14.7 deg, median 3.0 deg" in line
    assert "2 of 3 within 15 deg" in line
    # a run from before the symmetric error was measured reads as it did
    older = [{k: q[k] for k in ("azimuth_error", "elevation_error")} for q in queries]
    assert "symmetries" not in _pose_lines(older)[1]


def test_the_transfer_settings_nest_and_keep_the_protocols_defaults(tmp_path, capsys):
    """``transfer:`` holds every TransferConfig field; keys it leaves out keep the protocol's defaults (2 scales),
    not TransferConfig's; an unknown key, a field the protocol owns and an ablation's switch are one-line errors."""
    from dataclasses import replace

    from mesh2tex.config import load_config
    from mesh2tex.evaluation.protocol_config import ProtocolConfig
    from mesh2tex.metrics.evaluate import EvaluateConfig

    cfg = load_config(ProtocolConfig, protocol_yaml(tmp_path / "p.yaml", transfer={"w_anchor": 10, "latent_iters": 7}))
    assert (cfg.transfer.w_anchor, cfg.transfer.latent_iters, cfg.transfer.scales, cfg.transfer.patch_scales) == (
        10.0,
        7,
        1,
        0,
    )
    assert cfg.transfer_config().resolution == cfg.resolution == 32, "the transfer's resolution is the protocol's"
    # A shared field replaced on a built config is the one every transfer and the set metrics then take.
    changed = replace(cfg, resolution=48, seed=5)
    assert (changed.transfer_config().resolution, changed.transfer_config().seed) == (48, 5)
    assert (changed.evaluate_config().resolution, changed.evaluate_config().seed) == (48, 5)
    assert load_config(ProtocolConfig, overrides={"transfer.w_colour": 1}).transfer.scales == 2
    for fields, says in (
        ({"w_anchr": 1}, "unknown key(s) ['w_anchr']"),
        ({"seed": 3}, "transfer: seed cannot be set there"),
        ({"use_noc": False}, "choose an ablation"),
    ):
        assert (
            main(
                protocol_args(
                    tmp_path, tmp_path / "o", "--config", str(protocol_yaml(tmp_path / "bad.yaml", transfer=fields))
                )
            )
            == 2
        )
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, err
    assert main(["evaluate", "--protocols", "--latent-iters", "9", "--print-config"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["transfer"]["latent_iters"] == 9
    # A config of the layout before the nesting is told where its keys went.
    assert (
        main(
            protocol_args(
                tmp_path, tmp_path / "o", "--config", str(protocol_yaml(tmp_path / "old.yaml", latent_iters=5))
            )
        )
        == 2
    )
    assert "key(s) moved: latent_iters -> transfer.latent_iters" in capsys.readouterr().err
    # The set metrics' settings nest the same way, and take the protocol's resolution and seed.
    cfg = load_config(ProtocolConfig, overrides={"resolution": 48, "seed": 3, "evaluate.kid_subsets": 7})
    assert cfg.evaluate_config() == EvaluateConfig(resolution=48, seed=3, kid_subsets=7)
    assert (
        main(
            protocol_args(
                tmp_path, tmp_path / "o", "--config", str(protocol_yaml(tmp_path / "bad.yaml", evaluate={"seed": 5}))
            )
        )
        == 2
    )
    assert "evaluate: seed cannot be set there" in capsys.readouterr().err


def test_the_cache_fingerprint_keeps_the_layout_of_earlier_runs(tmp_path):
    """The settings finished transfers are kept with (``transfers/settings.json``) are those the runs made
    before the transfer's settings were nested wrote for the same settings, so their folders still resume."""
    from dataclasses import asdict

    from mesh2tex.config import config_from_dict
    from mesh2tex.errors import InputError
    from mesh2tex.evaluation.cache import TransferCache
    from mesh2tex.evaluation.protocol_config import NOT_TRANSFER, ProtocolConfig, cache_settings

    cfg = config_from_dict(
        ProtocolConfig, {"device": "cpu", "transfer": {"latent_iters": 50, "refine_iters": 150, "w_anchor": 10.0}}
    )
    settings = cache_settings(cfg, True)
    assert settings.pop("transfer_config") == {
        k: v for k, v in asdict(cfg.transfer).items() if k not in ("device", *NOT_TRANSFER)
    }
    assert settings == {
        "resolution": 64,
        "latent_iters": 50,
        "refine_iters": 150,
        "patch_size": 32,
        "scales": 2,
        "pose_search": True,
        "latents": 4,
        "views": 6,
        "features": "auto",
        "kid_subsets": 100,
        "seed": 0,
        "device": "cpu",
        "vgg_weights": "",
        "inception_weights": "",
        "transfer": {"w_anchor": 10.0},
        "generator_lit": True,
    }
    plain = cache_settings(
        config_from_dict(ProtocolConfig, {"transfer": {"patch_scales": 2, "pose_search": False}}), False
    )
    assert plain["patch_scales"] == 2 and "pose_search" not in plain and "transfer" not in plain

    fingerprint = {"settings": cache_settings(cfg, True), "inputs": {"gan": "abc"}}
    TransferCache(tmp_path, fingerprint)
    # A folder whose config set a field to its default (an older run's ``transfer: {w_colour: 10.0}``) still matches.
    TransferCache(
        tmp_path,
        {**fingerprint, "settings": {**fingerprint["settings"], "transfer": {"w_anchor": 10.0, "w_colour": 10.0}}},
    )
    other = config_from_dict(
        ProtocolConfig, {"device": "cpu", "transfer": {"latent_iters": 50, "refine_iters": 150, "w_anchor": 5.0}}
    )
    with pytest.raises(InputError, match="other settings"):
        TransferCache(tmp_path, {"settings": cache_settings(other, True), "inputs": {"gan": "abc"}})
