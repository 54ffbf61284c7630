"""Shipped models: a trained checkpoint exported for inference (float16) and named instead of a path."""

from __future__ import annotations

import pytest
import torch

from mesh2tex.cli import main
from mesh2tex.errors import InputError
from mesh2tex.io.checkpoint import check_training_checkpoint, load_checkpoint
from mesh2tex.models import MODEL_FILES, export_inference_checkpoint, list_models, load_generator, resolve_checkpoint


def load_build_model():
    """models/build_model.py, a script rather than a package module, loaded as a module."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "models" / "build_model.py"
    spec = importlib.util.spec_from_file_location("build_model", path)
    build_model = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build_model)
    return build_model


def test_an_exported_model_is_named_like_a_path_and_gives_the_same_textures(tiny_gan, tmp_path, monkeypatch, capsys):
    models = tmp_path / "models"
    (models / "tiny").mkdir(parents=True)
    source = tiny_gan / "run" / "checkpoint.safetensors"
    export_inference_checkpoint(source, "gan", models / "tiny" / MODEL_FILES["gan"])
    monkeypatch.setenv("MESH2TEX_MODELS", str(models))
    assert list_models() == ["tiny"]
    groups, meta = load_checkpoint(models / "tiny" / MODEL_FILES["gan"], kind="gan")
    assert set(groups) == {"generator_ema"} and "rng" not in meta
    with pytest.raises(InputError, match="an inference checkpoint"):  # not mistaken for a training state
        check_training_checkpoint(models / "tiny" / MODEL_FILES["gan"], "gan")
    assert all(t.dtype == torch.float16 for t in groups["generator_ema"].values() if t.is_floating_point())
    assert (models / "tiny" / MODEL_FILES["gan"]).stat().st_size < source.stat().st_size / 4

    shipped = load_generator("tiny", torch.device("cpu")).network
    full = load_generator(source, torch.device("cpu")).network
    for (name, a), b in zip(shipped.state_dict().items(), full.state_dict().values()):
        assert a.dtype == b.dtype and torch.allclose(a, b, rtol=2e-3, atol=2e-3), name

    out = tmp_path / "gen"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "tiny",
                "--mesh",
                str(tiny_gan / "shapes" / "box0.npz"),
                "--out",
                str(out),
                "--seeds",
                "0",
                "--views",
                "1",
                "--resolution",
                "32",
                "--texture-size",
                "32",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    assert (out / "seed0.glb").is_file()
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "nosuchmodel",
                "--mesh",
                str(tiny_gan / "shapes" / "box0.npz"),
                "--out",
                str(tmp_path / "x"),
                "--device",
                "cpu",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert (
        "nosuchmodel: no such checkpoint file or shipped model (shipped models: tiny)" in err and "Traceback" not in err
    )


def test_a_model_without_a_pose_network_says_so(tiny_gan, tmp_path, monkeypatch):
    models = tmp_path / "models"
    (models / "tiny").mkdir(parents=True)
    export_inference_checkpoint(
        tiny_gan / "run" / "checkpoint.safetensors", "gan", models / "tiny" / MODEL_FILES["gan"]
    )
    monkeypatch.setenv("MESH2TEX_MODELS", str(models))
    with pytest.raises(InputError, match="has no pose network"):
        resolve_checkpoint("tiny", "pose")
    assert resolve_checkpoint(str(tiny_gan / "run" / "checkpoint.safetensors"), "gan").is_file()


def test_the_shipped_models_load(monkeypatch):
    """Every model in the package's models/ folder (mesh2tex/models) loads and has all three networks."""
    monkeypatch.delenv("MESH2TEX_MODELS", raising=False)
    from mesh2tex.models import load_view_network

    for name in list_models():
        model = load_generator(name, torch.device("cpu"))
        assert (
            model.network.cfg.input_features > 0
            and model.iteration > 0
            and model.resolution > 0
            and model.hierarchy_recorded
        )
        for kind in ("pose", "noc"):
            load_view_network(name, kind)


def test_each_rebuild_recipe_is_a_valid_gan_config_and_matches_its_card(tmp_path):
    """models/build_model.py's recipes load as train gan configs, and each shipped card's iteration
    count (the one its validation pick chose, for a recipe that picks), world and training settings are
    its recipe's (the rebuild command on the card has no --gan-iters)."""
    import json
    from pathlib import Path

    import yaml
    from mesh2tex.train.gan_config import TrainGanConfig

    from mesh2tex.config import load_config
    from mesh2tex.nn.view_nets import ViewTrainConfig

    build_model = load_build_model()
    root = Path(__file__).resolve().parents[1]
    for category, recipe in build_model.RECIPES.items():
        gan_config = build_model.recipe_gan_config(recipe)
        written = tmp_path / f"{category}.yaml"  # as build_model.py hands it to train gan
        written.write_text(yaml.safe_dump(gan_config, sort_keys=False))
        cfg = load_config(TrainGanConfig, written)
        assert recipe["views_gan_iteration"] % cfg.snapshot_every == 0  # the views' snapshot is kept
        card = json.loads((root / "mesh2tex" / "models" / category / "card.json").read_text())
        assert card.get("gan_trained_iterations", card["gan_iterations"]) == recipe["gan_iters"]
        if recipe.get("pick"):  # the exported generator is the snapshot the validation world ranked first
            figures = {int(k): v for k, v in card["pick"]["figures"].items()}
            assert card["gan_iterations"] == build_model.best_snapshot(figures, card["pick"]["min_spread"])
        else:
            assert card["gan_iterations"] == recipe["gan_iters"]
        assert card["views_gan_iteration"] == recipe["views_gan_iteration"]
        assert card["world"] == build_model.recipe_world(recipe)  # the card's world is the one the recipe prepares
        assert card["gan"]["config"] == gan_config  # and its training settings are the recipe's
        if "mask" in card:  # so are its mask network's, and they load as a train mask config
            mask_settings = build_model.recipe_mask(recipe)
            assert card["mask"] == mask_settings
            written = tmp_path / f"{category}_mask.yaml"
            written.write_text(yaml.safe_dump(mask_settings["config"]))
            loaded = load_config(ViewTrainConfig, written)
            assert loaded.room_share == mask_settings["config"].get("room_share", 0.0)
    assert build_model.RECIPES["chair"]["loss"]["diversity_start"] == 3500


def test_a_validation_pick_is_reused_only_for_the_run_it_measured(tmp_path, monkeypatch):
    """build_model.py --pick keeps each snapshot's validation figure in WORK/validation/pick.json; a work
    folder copied for another seed's run measures that run's snapshots instead of taking the first run's."""
    from pathlib import Path

    build_model = load_build_model()
    measured = []

    def protocol(world, shapes, snapshot, cfg):
        measured.append(Path(snapshot))
        return {
            "gap_closed": 0.5 if "iter0000200" in Path(snapshot).name else 0.1,
            "diversity": {"trained_spread_vs_photo_set": 0.8},
        }

    monkeypatch.setattr(build_model, "prepare_world", lambda *args: None)
    monkeypatch.setattr(build_model, "prepare_split", lambda *args: None)
    monkeypatch.setattr(build_model, "run_generation_protocol", protocol)
    (tmp_path / "validation").mkdir()
    runs = []
    for seed in (0, 1):
        run = tmp_path / f"gan{seed}"
        (run / "snapshots").mkdir(parents=True)
        for iteration in (100, 200, 300):
            (run / "snapshots" / f"iter{iteration:07d}.safetensors").write_bytes(b"")
        runs.append(run)
    pick = {"from": 100, "every": 100}
    best, figures = build_model.pick_snapshot(tmp_path, "chair", "real", runs[0], 300, pick, [])
    assert best.name == "iter0000200.safetensors" and len(measured) == 3
    build_model.pick_snapshot(tmp_path, "chair", "real", runs[0], 300, pick, [])
    assert len(measured) == 3, "the same run's figures are reused"
    build_model.pick_snapshot(tmp_path, "chair", "real", runs[1], 300, pick, [])
    assert len(measured) == 6 and all(path.parent.parent == runs[1] for path in measured[3:]), (
        "another run is measured anew"
    )


def test_the_pick_passes_over_a_snapshot_whose_latents_all_paint_the_same_chair(tmp_path, monkeypatch, capsys):
    """A collapsed generator (colour spread under PICK_MIN_SPREAD of the photo set's) is not picked for its
    gap; when every snapshot is collapsed the best gap is taken with a warning."""
    from pathlib import Path

    build_model = load_build_model()
    floor = build_model.PICK_MIN_SPREAD
    figures = {100: (0.3, floor + 0.2), 200: (0.6, floor - 0.2), 300: (0.4, floor)}

    def protocol(world, shapes, snapshot, cfg):
        gap, spread = figures[int(Path(snapshot).stem[4:])]
        return {"gap_closed": gap, "diversity": {"trained_spread_vs_photo_set": spread}}

    monkeypatch.setattr(build_model, "prepare_world", lambda *args: None)
    monkeypatch.setattr(build_model, "prepare_split", lambda *args: None)
    monkeypatch.setattr(build_model, "run_generation_protocol", protocol)
    (tmp_path / "validation").mkdir()
    run = tmp_path / "gan"
    (run / "snapshots").mkdir(parents=True)
    for iteration in figures:
        (run / "snapshots" / f"iter{iteration:07d}.safetensors").write_bytes(b"")
    best, kept = build_model.pick_snapshot(tmp_path, "chair", "real", run, 300, {"from": 100, "every": 100}, [])
    assert best.name == "iter0000300.safetensors", "the best gap among the varied snapshots, not the collapsed one's"
    assert kept[200] == {"gap": 0.6, "spread": round(floor - 0.2, 4)}
    assert "warning" not in capsys.readouterr().out

    figures.update({100: (0.3, 0.0), 300: (0.4, 0.0)})
    (tmp_path / "validation" / "pick.json").unlink()
    best, _ = build_model.pick_snapshot(tmp_path, "chair", "real", run, 300, {"from": 100, "every": 100}, [])
    assert best.name == "iter0000200.safetensors" and "warning" in capsys.readouterr().out


def test_keep_mask_takes_the_mask_record_of_a_folder_that_has_one_of_the_recipes_settings(tmp_path):
    """build_model.py --keep-mask: a model folder without a mask network, or with one of other settings, is
    refused before any training; one of the recipe's settings gives its card's training record to the new card."""
    import json

    import pytest

    build_model = load_build_model()
    settings = build_model.recipe_mask(build_model.RECIPES["chair"])
    with pytest.raises(SystemExit, match="--keep-mask needs"):
        build_model.keep_mask_record(tmp_path, 4000, settings)
    (tmp_path / build_model.MODEL_FILES["mask"]).write_bytes(b"")
    record = {"mask": settings, "mask_iterations": 4000, "mask_training": {"command": "mesh2tex train mask"}}
    (tmp_path / "card.json").write_text(json.dumps(record))
    assert build_model.keep_mask_record(tmp_path, 4000, settings) == {
        "mask_training": {"command": "mesh2tex train mask"}
    }
    with pytest.raises(SystemExit, match="at 2000 steps"):
        build_model.keep_mask_record(tmp_path, 2000, settings)
    with pytest.raises(SystemExit, match="--keep-mask needs"):  # a mask trained without the recipe's rooms
        build_model.keep_mask_record(tmp_path, 4000, build_model.MASK)


def test_the_mask_network_trains_beside_the_build_on_half_the_cores_and_its_failure_stops_the_build(tmp_path):
    """build_model.py starts `train mask` in a process of its own (it needs only the world): half the cores each
    unless the user set the threads; a mask training that fails as it starts stops the build at once with the path
    of its output, which holds the command's own one-line error."""
    import pytest

    build_model = load_build_model()
    assert build_model.split_threads({}, cpu_count=2) == (1, {"MESH2TEX_THREADS": "1"})
    assert build_model.split_threads({}, cpu_count=16) == (8, {"MESH2TEX_THREADS": "8"})
    assert build_model.split_threads({}, cpu_count=1) == (1, {"MESH2TEX_THREADS": "1"})
    assert build_model.split_threads({"OMP_NUM_THREADS": "3"}, cpu_count=16) == (None, {})
    commands: list[str] = []
    log = tmp_path / "mask.log"
    argv = ["train", "mask", "--shapes", str(tmp_path / "missing"), "--out", str(tmp_path / "mask"), "--iters", "1"]
    with pytest.raises(SystemExit, match="mask network's training failed") as stopped:
        build_model.start_mask_training(argv, log, {"MESH2TEX_THREADS": "1"}, commands)
    assert commands == ["mesh2tex " + " ".join(argv)]
    assert str(log) in str(stopped.value), "at once, not after the GAN"
    assert "missing" in log.read_text(), "the mask command's own error, naming the folder"
