"""``mesh2tex evaluate --protocols``: the paper's synthetic protocols on a real (tiny) world and checkpoints."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
import torch
import yaml
from conftest import TINY_GAN as TINY
from conftest import make_tiny_world

from mesh2tex.cli import main
from mesh2tex.evaluation.paired import compare_to_full, oracle_check, paired_query_tests, paired_query_wins
from mesh2tex.evaluation.report import BASELINES, PROTOCOLS, protocols_markdown
from mesh2tex.evaluation.world import load_world, other_shape_name, photo_frame_view
from mesh2tex.geometry.mesh_io import load_mesh
from mesh2tex.io.images import load_mask
from mesh2tex.transfer import ABLATIONS


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """A 3-chair world (1 held-out shape, 2 queries), its query shape and one training shape prepared,
    a GAN after 2 iterations and pose and NOC networks after 2 steps."""
    root = tmp_path_factory.mktemp("protocols")
    index = make_tiny_world(root, views=2, resolution=48, query_views=2)
    world, shapes = root / "world", root / "shapes"
    (root / "tiny.yaml").write_text(yaml.safe_dump(TINY))
    assert main(["train", "gan", "--shapes", str(shapes), "--images", str(world), "--out", str(root / "gan"),
                 "--config", str(root / "tiny.yaml"), "--iters", "2", "--batch", "2", "--views", "1", "--resolution", "16",
                 "--device", "cpu"]) == 0
    (root / "view.yaml").write_text("width: 4\ndata:\n  views_per_material: 4\n")
    for kind in ("pose", "noc"):
        assert main(["train", kind, "--shapes", str(shapes), "--out", str(root / kind), "--config", str(root / "view.yaml"),
                     "--iters", "2", "--samples", "8", "--resolution", "32", "--batch", "4", "--device", "cpu"]) == 0
    _yaml(root / "protocols.yaml")
    return root, index


def protocol_args(root, out, *extra):
    return ["evaluate", "--protocols", "--world", str(root / "world"), "--shapes", str(root / "shapes"),
            "--checkpoint", str(root / "gan" / "checkpoint.safetensors"),
            "--pose-checkpoint", str(root / "pose" / "checkpoint.safetensors"),
            "--noc-checkpoint", str(root / "noc" / "checkpoint.safetensors"), "--out", str(out),
            "--latent-iters", "2", "--refine-iters", "1", "--kid-subsets", "2", "--device", "cpu",
            "--config", str(root / "protocols.yaml"), *extra]


def test_every_protocol_and_ablation_is_run_and_tabled(setup, tmp_path, monkeypatch):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "no_weights"))  # never find (or fetch) weights
    root, index = setup
    out = tmp_path / "eval"
    assert main(protocol_args(root, out)) == 0
    result = json.loads((out / "protocols.json").read_text())
    assert list(result["protocols"]) == list(PROTOCOLS)
    assert result["counts"] == {"queries": 2, "query_shapes": 1}
    unconditional = result["protocols"]["unconditional"]
    assert unconditional["counts"] == {"renders": 2, "images": len(index["images"])}
    assert np.isfinite(unconditional["metrics"]["swd"]) and "kid_randvgg" in unconditional["metrics"]

    held_out = index["split"]["query_shapes"][0]
    for protocol in ("known_pose", "unknown_pose", "other_shape"):
        entry = result["protocols"][protocol]
        assert list(entry["methods"]) == list(BASELINES) + list(ABLATIONS)
        assert [q["query"] for q in entry["queries"]] == [q["image"].split("/")[-1][:-4] for q in index["queries"]]
        exact = protocol != "other_shape"
        for name, method in entry["methods"].items():
            assert len(method["per_query"]) == 2
            for side in ("seen", "unseen"):  # the photo's view and the views it does not show, apart
                assert np.isfinite(method["query"][f"{side} part_delta_e"]) and method["query"][f"{side} part_delta_e"] >= 0
                assert np.isfinite(method["query"][f"{side} swd"])
                assert (f"{side} lowpass_psnr" in method["query"]) == exact and (f"{side} psnr" in method["query"]) == exact
        # The ground truth wins every column on exact geometry: a metric it loses is broken.
        if exact:
            assert entry["oracle_loses"] == [], f"{protocol}: the oracle loses {entry['oracle_loses']}"
        targets = {q["shape"] for q in entry["queries"]}
        assert targets == ({held_out} if protocol != "other_shape" else {index["split"]["train_shapes"][0]})
        assert set(result["comparison"][protocol]) == set(BASELINES) | {"no_noc", "no_patches", "no_refine", "paper"}
    # The known pose is the sidecar's; stage 2 ran for the full method and not for no_refine.
    assert all(q["azimuth_error"] == 0 and q["elevation_error"] == 0 for q in result["protocols"]["known_pose"]["queries"])
    rows = result["protocols"]["known_pose"]["methods"]
    assert "refine" in rows["full"]["per_query"][0]["loss_last"] and "refine" not in rows["no_refine"]["per_query"][0]["loss_last"]

    table = (out / "protocols.md").read_text()
    for title in ("| w/o NOC |", "| w/o patches |", "| w/o surface features (no refine) |", "| full method |",
                  "| ground-truth texture (oracle) |", "| flat mean colour of the photo |", "| photo back-projection |",
                  "| generator's mean texture (w_avg) |", "exact geometry, unknown pose", "transfer to another shape",
                  "seen per-part ΔE ↓", "unseen low-pass PSNR ↑", "seen object SWD ↓"):
        assert title in table
    assert (out / "renders" / "known_pose" / "backprojection" / f"{entry['queries'][0]['query']}.png").is_file()
    assert (out / "renders" / "other_shape" / "full").is_dir()
    assert main(protocol_args(root, out)) == 2, "existing results are kept without --overwrite"


def test_an_automaton_fitted_to_the_photo_is_judged_beside_the_baselines_when_asked_for(setup, tmp_path, monkeypatch):
    """``--baselines ...,automaton`` adds a mesh automaton fitted to the photo (no GAN) as one more row, scored
    alike; its fit is set under ``transfer: automaton:`` and is left out of the transfer cache's fingerprint."""
    from mesh2tex.config import config_from_dict
    from mesh2tex.evaluation.protocol_config import ProtocolConfig, cache_settings

    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "no_weights"))
    root, _ = setup
    config = _yaml(tmp_path / "automaton.yaml", transfer={"automaton": {"iters": 3, "steps_min": 2, "steps_max": 3, "final_steps": 2}})
    out = tmp_path / "eval"
    args = protocol_args(root, out, "--only", "known_pose", "--ablations", "full", "--baselines", "oracle,flat_colour,automaton")
    args[args.index("--config") + 1] = str(config)
    assert main(args) == 0
    entry = json.loads((out / "protocols.json").read_text())["protocols"]["known_pose"]
    assert list(entry["methods"]) == ["oracle", "flat_colour", "automaton", "full"]
    automaton = entry["methods"]["automaton"]
    assert len(automaton["per_query"]) == 2 and np.isfinite(automaton["query"]["seen part_delta_e"])
    assert np.isfinite(automaton["per_query"][0]["loss_last"])
    assert "| automaton fitted to the photo (no GAN) |" in (out / "protocols.md").read_text()
    plain, tuned = (config_from_dict(ProtocolConfig, d) for d in ({}, {"transfer": {"automaton": {"iters": 7}, "texture_format": "webp"}}))
    assert cache_settings(plain, True) == cache_settings(tuned, True)


def test_true_pose_frame_lines_up_with_the_photo(setup):
    """Exact geometry is judged pixel-aligned: the world mesh seen through the sidecar camera, framed by
    the photo's box, covers the photo's mask (a wrong pose convention would overlap far less)."""
    root, index = setup
    world = load_world(root / "world")
    for query in world.queries:
        vertices, faces = load_mesh(root / "world" / "meshes" / f"{query.shape}.obj")
        exact = SimpleNamespace(vertices=[np.asarray(vertices, np.float32)], triangles=lambda level: faces)
        view = photo_frame_view(exact, query, 48, 0.1)
        photo_mask = torch.from_numpy(np.asarray(load_mask(query.mask))).float()
        from mesh2tex.render import crop_square

        photo_crop = crop_square(photo_mask[None, None], view.box, 48) > 0.5
        covered = view.mask > 0.5
        iou = float((covered & photo_crop).sum() / (covered | photo_crop).sum())
        assert iou > 0.8, f"{query.name}: silhouette IoU {iou:.2f}"


def test_comparison_counts_wins_by_each_metrics_direction():
    methods = {
        "full": {"query": {"seen part_delta_e": 5.0, "seen lowpass_psnr": 20.0, "unseen swd": 30.0, "seen psnr": 18.0}},
        "flat_colour": {"query": {"seen part_delta_e": 9.0, "seen lowpass_psnr": 21.0, "unseen swd": 30.0, "seen psnr": 17.0}},
    }
    c = compare_to_full(methods)["flat_colour"]
    assert c["full_better"] == {"seen part_delta_e": True, "seen lowpass_psnr": False, "unseen swd": False, "seen psnr": True}
    assert (c["wins"], c["ties"], c["metrics"]) == (2, 1, 4)


def test_oracle_check_names_the_columns_the_ground_truth_loses():
    methods = {"oracle": {"query": {"seen part_delta_e": 1.0, "seen psnr": 30.0}},
               "flat_colour": {"query": {"seen part_delta_e": 9.0, "seen psnr": 31.0}}}
    assert oracle_check(methods) == ["seen psnr"]
    methods["flat_colour"]["query"]["seen psnr"] = 20.0
    assert oracle_check(methods) == []


def test_paired_query_wins_compare_the_same_queries():
    full = [{"query": "a", "seen psnr": 20.0, "seen part_delta_e": 0.2}, {"query": "b", "seen psnr": 18.0, "seen part_delta_e": 0.5}]
    other = [{"query": "b", "seen psnr": 17.0, "seen part_delta_e": 0.5}, {"query": "a", "seen psnr": 21.0, "seen part_delta_e": 0.3}]
    assert paired_query_wins(full, other) == {"seen psnr": [1, 2], "seen part_delta_e": [1, 2]}


def test_paired_tests_separate_a_consistent_advantage_from_noise():
    names = [f"q{i}" for i in range(8)]
    other = [{"query": n, "seen psnr": 15.0 + i, "seen part_delta_e": 0.5} for i, n in enumerate(names)]
    # Better on every query (higher PSNR, lower colour error): the smallest exact p of 8 pairs, 2/256.
    better = [{"query": n, "seen psnr": 15.5 + i + 0.1 * i, "seen part_delta_e": 0.4} for i, n in enumerate(names)]
    tests = paired_query_tests(better, other)
    assert tests["seen psnr"]["p_wilcoxon"] < 0.01 and tests["seen psnr"]["mean_difference"] > 0
    assert tests["seen part_delta_e"]["p_wilcoxon"] < 0.01 and abs(tests["seen part_delta_e"]["mean_difference"] - 0.1) < 1e-9
    # Wins and losses of matched sizes: no evidence either way.
    mixed = [{"query": n, "seen psnr": 15.0 + i + (1.0 if i % 2 else -1.0), "seen part_delta_e": 0.5} for i, n in enumerate(names)]
    tests = paired_query_tests(mixed, other)
    assert tests["seen psnr"]["p_wilcoxon"] > 0.5 and tests["seen psnr"]["mean_difference"] == 0
    assert tests["seen part_delta_e"]["p_wilcoxon"] is None  # every difference is 0


def test_an_interrupted_run_resumes_without_redoing_finished_transfers(setup, tmp_path, monkeypatch):
    import mesh2tex.transfer

    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "no_weights"))
    root, _ = setup
    out = tmp_path / "eval"
    args = protocol_args(root, out, "--only", "known_pose", "--ablations", "full,no_refine")
    real, calls = mesh2tex.transfer.transfer_texture, []

    def interrupted(*a, **k):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(mesh2tex.transfer, "transfer_texture", interrupted)
    assert main(args) == 130, "Ctrl-C stops the run with the shell's interrupt status"
    assert len(list((out / "transfers").rglob("*.npz"))) == 3 and not (out / "protocols.json").exists()
    changed = protocol_args(root, out, "--only", "known_pose", "--ablations", "full,no_refine", "--seed", "5")
    assert main(changed) == 2, "transfers made with other settings are not mixed with new ones"

    counted = []
    monkeypatch.setattr(mesh2tex.transfer, "transfer_texture", lambda *a, **k: counted.append(1) or real(*a, **k))
    assert main(args) == 0
    assert len(counted) == 1, "only the transfer that had not finished runs again (2 queries x 2 ablations - 3)"
    result = json.loads((out / "protocols.json").read_text())
    assert all(len(a["per_query"]) == 2 for a in result["protocols"]["known_pose"]["methods"].values())

    wider = protocol_args(root, out, "--only", "known_pose", "--ablations", "full,no_refine,no_noc", "--overwrite")
    assert main(wider) == 0
    assert len(counted) == 3, "a run with one more ablation makes only that ablation's transfers"
    result = json.loads((out / "protocols.json").read_text())
    assert set(result["comparison"]["known_pose"]) == set(BASELINES) | {"no_refine", "no_noc"}

    judged_apart = protocol_args(root, out, "--only", "known_pose", "--ablations", "full", "--config",
                                 str(_yaml(tmp_path / "albedo.yaml", lighting="albedo", unseen_views=2)), "--overwrite")
    assert main(judged_apart) == 0
    assert len(counted) == 3, "judging with other lighting and views re-judges the kept transfers, it does not redo them"


def test_other_shape_is_never_the_query_shape():
    assert other_shape_name("b", ["a", "b", "c"]) == "c"
    assert other_shape_name("c", ["a", "b", "c"]) == "a"
    with pytest.raises(Exception, match="second prepared shape"):
        other_shape_name("a", ["a"])


def test_bad_inputs_name_the_problem(setup, tmp_path, capsys):
    root, index = setup
    assert main(protocol_args(root, tmp_path / "o", "--world", str(tmp_path))) == 2
    assert "no index.json" in capsys.readouterr().err
    empty = tmp_path / "shapes"
    empty.mkdir()
    (empty / "other.npz").write_bytes((root / "shapes" / f"{index['split']['train_shapes'][0]}.npz").read_bytes())
    assert main(protocol_args(root, tmp_path / "o", "--shapes", str(empty), "--only", "known_pose")) == 2
    assert f"no prepared shape for {index['split']['query_shapes'][0]}" in capsys.readouterr().err
    assert main(protocol_args(root, tmp_path / "o", "--only", "table9")) == 2
    assert "unknown protocol, ablation or baseline table9" in capsys.readouterr().err
    assert main(["evaluate", "--out", str(tmp_path / "o")]) == 2
    assert "needs --renders and --images" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_markdown_marks_the_best_value_and_says_which_way_is_better():
    rows = lambda value: [{"query": "q", "seen part_delta_e": value}]
    result = {"settings": {"latent_iters": 1, "refine_iters": 1, "resolution": 64, "patch_size": 32}, "world": "w", "gan": "g",
              "counts": {"queries": 1}, "features": "f", "comparison": {},
              "protocols": {"known_pose": {"queries": [{"azimuth_error": 0.0, "elevation_error": 0.0}], "methods": {
                  "oracle": {"query": {"seen part_delta_e": 0.5}, "per_query": rows(0.5), "seconds": 0.0},
                  "flat_colour": {"query": {"seen part_delta_e": 9.0}, "per_query": rows(9.0), "seconds": 0.0},
                  "full": {"query": {"seen part_delta_e": 4.0}, "per_query": rows(4.0), "seconds": 1.0},
                  "no_noc": {"query": {"seen part_delta_e": 5.0}, "per_query": rows(5.0), "seconds": 1.0}}}}}
    table = protocols_markdown(result)
    assert "| method | seen per-part ΔE ↓ | seconds |" in table
    assert "| full method | **4** | 1 |" in table and "| w/o NOC | 5 | 1 |" in table
    assert "| ground-truth texture (oracle) | 0.5 | 0 |" in table and "The oracle wins every column." in table
    assert "seen per-part ΔE 0.44 of the flat colour's, lower on 1 of 1 queries" in table


def _yaml(path, transfer=None, **fields):
    path.write_text(yaml.safe_dump({"latents": 1, "views": 2, "resolution": 32, **fields,
                                    "transfer": {"patch_size": 16, "scales": 1, **(transfer or {})}}))
    return path


def test_the_transfer_settings_nest_and_keep_the_protocols_defaults(tmp_path, capsys):
    """``transfer:`` holds every TransferConfig field; keys it leaves out keep the protocol's defaults (2 scales),
    not TransferConfig's; an unknown key, a field the protocol owns and an ablation's switch are one-line errors."""
    from dataclasses import replace

    from mesh2tex.config import load_config
    from mesh2tex.evaluation.protocol_config import ProtocolConfig
    from mesh2tex.metrics.evaluate import EvaluateConfig

    cfg = load_config(ProtocolConfig, _yaml(tmp_path / "p.yaml", transfer={"w_anchor": 10, "latent_iters": 7}))
    assert (cfg.transfer.w_anchor, cfg.transfer.latent_iters, cfg.transfer.scales, cfg.transfer.patch_scales) == (10.0, 7, 1, 0)
    assert cfg.transfer_config().resolution == cfg.resolution == 32, "the transfer's resolution is the protocol's"
    # A shared field replaced on a built config is the one every transfer and the set metrics then take.
    changed = replace(cfg, resolution=48, seed=5)
    assert (changed.transfer_config().resolution, changed.transfer_config().seed) == (48, 5)
    assert (changed.evaluate_config().resolution, changed.evaluate_config().seed) == (48, 5)
    assert load_config(ProtocolConfig, overrides={"transfer.w_colour": 1}).transfer.scales == 2
    for fields, says in (({"w_anchr": 1}, "unknown key(s) ['w_anchr']"), ({"seed": 3}, "transfer: seed cannot be set there"),
                         ({"use_noc": False}, "choose an ablation")):
        assert main(protocol_args(tmp_path, tmp_path / "o", "--config", str(_yaml(tmp_path / "bad.yaml", transfer=fields)))) == 2
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, err
    assert main(["evaluate", "--protocols", "--latent-iters", "9", "--print-config"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["transfer"]["latent_iters"] == 9
    # A config of the layout before the nesting is told where its keys went.
    assert main(protocol_args(tmp_path, tmp_path / "o", "--config", str(_yaml(tmp_path / "old.yaml", latent_iters=5)))) == 2
    assert "key(s) moved: latent_iters -> transfer.latent_iters" in capsys.readouterr().err
    # The set metrics' settings nest the same way, and take the protocol's resolution and seed.
    cfg = load_config(ProtocolConfig, overrides={"resolution": 48, "seed": 3, "evaluate.kid_subsets": 7})
    assert cfg.evaluate_config() == EvaluateConfig(resolution=48, seed=3, kid_subsets=7)
    assert main(protocol_args(tmp_path, tmp_path / "o", "--config", str(_yaml(tmp_path / "bad.yaml", evaluate={"seed": 5})))) == 2
    assert "evaluate: seed cannot be set there" in capsys.readouterr().err


def test_the_cache_fingerprint_keeps_the_layout_of_earlier_runs(tmp_path):
    """The settings finished transfers are kept with (``transfers/settings.json``) are those the runs made
    before the transfer's settings were nested wrote for the same settings, so their folders still resume."""
    from dataclasses import asdict

    from mesh2tex.config import config_from_dict
    from mesh2tex.errors import InputError
    from mesh2tex.evaluation.cache import TransferCache
    from mesh2tex.evaluation.protocol_config import NOT_TRANSFER, ProtocolConfig, cache_settings

    cfg = config_from_dict(ProtocolConfig, {"device": "cpu", "transfer": {"latent_iters": 50, "refine_iters": 150, "w_anchor": 10.0}})
    settings = cache_settings(cfg, True)
    assert settings.pop("transfer_config") == {k: v for k, v in asdict(cfg.transfer).items() if k not in ("device", *NOT_TRANSFER)}
    assert settings == {"resolution": 64, "latent_iters": 50, "refine_iters": 150, "patch_size": 32, "scales": 2, "pose_search": True,
                        "latents": 4, "views": 6, "features": "auto", "kid_subsets": 100, "seed": 0, "device": "cpu", "vgg_weights": "",
                        "inception_weights": "", "transfer": {"w_anchor": 10.0}, "generator_lit": True}
    plain = cache_settings(config_from_dict(ProtocolConfig, {"transfer": {"patch_scales": 2, "pose_search": False}}), False)
    assert plain["patch_scales"] == 2 and "pose_search" not in plain and "transfer" not in plain

    fingerprint = {"settings": cache_settings(cfg, True), "inputs": {"gan": "abc"}}
    TransferCache(tmp_path, fingerprint)
    # A folder whose config set a field to its default (an older run's ``transfer: {w_colour: 10.0}``) still matches.
    TransferCache(tmp_path, {**fingerprint, "settings": {**fingerprint["settings"], "transfer": {"w_anchor": 10.0, "w_colour": 10.0}}})
    other = config_from_dict(ProtocolConfig, {"device": "cpu", "transfer": {"latent_iters": 50, "refine_iters": 150, "w_anchor": 5.0}})
    with pytest.raises(InputError, match="other settings"):
        TransferCache(tmp_path, {"settings": cache_settings(other, True), "inputs": {"gan": "abc"}})
