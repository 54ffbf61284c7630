"""`train pose` / `train noc` / `train mask`: they learn from rendered views, checkpoint without pickle, resume, and
load back."""

import json

import numpy as np
import pytest
import torch
import trimesh
from mesh2tex.train.view_nets import render_view_dataset

from mesh2tex.cli import main
from mesh2tex.errors import InputError
from mesh2tex.geometry.prepare import prepare_shape
from mesh2tex.models import load_view_network
from mesh2tex.nn.view_nets import ViewDataConfig


@pytest.fixture(scope="module")
def shapes_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("shapes")
    box = trimesh.creation.box((0.4, 0.8, 0.3))
    prepare_shape(box.vertices, box.faces, face_count=96, levels=2, seed=0, source="box").save(folder / "box.npz")
    return folder


def test_rendered_views_carry_consistent_ground_truth(shapes_dir):
    from mesh2tex.geometry.prepared import PreparedShape

    shape = PreparedShape.load(shapes_dir / "box.npz")
    cfg = ViewDataConfig(samples=6, views_per_material=3, resolution=32)
    views = render_view_dataset([shape], cfg, seed=1)
    assert views["rgb"].shape == (6, 32, 32, 3) and views["noc"].shape == (6, 32, 32, 3)
    covered = views["mask"] > 127
    assert covered.any(axis=(1, 2)).all(), "every view shows the object"
    assert (views["noc"][~covered] == 0).all(), "NOC is zero off the object"
    assert ((views["elevation"] >= cfg.elevation_min) & (views["elevation"] <= cfg.elevation_max)).all()
    again = render_view_dataset([shape], cfg, seed=1)
    assert np.array_equal(views["rgb"], again["rgb"]), "deterministic for a seed"


def test_views_of_the_varied_world_take_its_materials(shapes_dir):
    """variety 'real' textures the views with the varied world's materials (the same cameras and masks
    as the boxy library's for a seed, other colours); 'boxy' stays what it was."""
    from mesh2tex.geometry.prepared import PreparedShape

    shape = PreparedShape.load(shapes_dir / "box.npz")
    boxy = render_view_dataset([shape], ViewDataConfig(samples=4, views_per_material=2, resolution=32), seed=3)
    real = render_view_dataset(
        [shape], ViewDataConfig(samples=4, views_per_material=2, resolution=32, variety="real"), seed=3
    )
    assert np.array_equal(boxy["mask"], real["mask"]) and np.array_equal(boxy["azimuth"], real["azimuth"])
    assert not np.array_equal(boxy["rgb"], real["rgb"])


def test_views_are_framed_like_the_query_photo(shapes_dir):
    """Training views are cropped around the object as 'infer transfer' crops a photo: the object's
    larger side spans 1 / (1 + 2 margin) of the view, centred, whatever the camera distance."""
    from mesh2tex.geometry.prepared import PreparedShape

    shape = PreparedShape.load(shapes_dir / "box.npz")
    margin, size = 0.1, 40
    cfg = ViewDataConfig(
        samples=8, views_per_material=4, resolution=size, frame_margin=margin, distance_min=1.2, distance_max=3.0
    )
    views = render_view_dataset([shape], cfg, seed=2)
    for mask, noc in zip(views["mask"] > 127, views["noc"]):
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        extent = max(rows[-1] + 1 - rows[0], cols[-1] + 1 - cols[0])
        assert abs(extent - size / (1 + 2 * margin)) <= 2
        assert abs((rows[0] + rows[-1] + 1) / 2 - size / 2) <= 2 and abs((cols[0] + cols[-1] + 1) / 2 - size / 2) <= 2
        assert (noc[~mask] == 0).all() and (noc[mask] > 0).any(axis=-1).all(), (
            "NOC on the object only, not darkened to 0"
        )
    whole = render_view_dataset(
        [shape],
        ViewDataConfig(
            samples=4, views_per_material=4, resolution=size, frame_margin=-1.0, distance_min=3.0, distance_max=3.0
        ),
        seed=2,
    )
    assert ((whole["mask"] > 127).sum(axis=(1, 2)) < (views["mask"][:4] > 127).sum(axis=(1, 2))).all(), (
        "frame_margin < 0 keeps the far view small"
    )


@pytest.mark.parametrize("kind", ["pose", "noc", "mask"])
def test_train_resume_and_load(kind, shapes_dir, tmp_path):
    run = tmp_path / kind
    config = tmp_path / "c.yaml"
    config.write_text("width: 8\nlog_every: 1\ndata:\n  views_per_material: 4\n")
    base = [
        "train",
        kind,
        "--shapes",
        str(shapes_dir),
        "--out",
        str(run),
        "--config",
        str(config),
        "--samples",
        "12",
        "--resolution",
        "32",
        "--batch",
        "4",
        "--device",
        "cpu",
    ]
    assert main(base + ["--iters", "2"]) == 0
    assert main(base + ["--iters", "2"]) == 2, "a finished run is not overwritten without --resume"
    assert main(base + ["--iters", "4", "--resume"]) == 0
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in records] == [1, 2, 3, 4]
    assert all(np.isfinite(r["loss"]) for r in records)
    net, cfg = load_view_network(run / "checkpoint.safetensors", kind)
    assert cfg.width == 8 and cfg.data.resolution == 32
    image = torch.zeros(1, 3, 32, 32)
    out = net(image) if kind in ("pose", "mask") else net(image, torch.ones(1, 1, 32, 32))
    assert out[0].shape == (1, 12) if kind == "pose" else out.shape == (1, {"noc": 3, "mask": 1}[kind], 32, 32)
    other = "noc" if kind == "pose" else "pose"
    with pytest.raises(InputError, match=f"expected a '{other}' checkpoint"):
        load_view_network(run / "checkpoint.safetensors", other)


def test_the_rate_settles_by_a_cosine_to_lr_end_at_the_last_step(shapes_dir, tmp_path):
    """``lr_end`` 0.1: the last step is taken at a tenth of ``lr`` (what the checkpoint's optimiser holds), also by a
    run resumed with more ``--iters`` (the cosine spans the iterations asked for); ``lr_end`` 1, the default, keeps
    the rate constant."""
    from mesh2tex.io.checkpoint import load_training_state
    from mesh2tex.nn.view_nets import ViewTrainConfig, build_network

    def last_rate(run):
        net = build_network("mask", ViewTrainConfig(width=8))
        opt = torch.optim.Adam(net.parameters(), lr=1.0)
        load_training_state(run / "checkpoint.safetensors", "mask", {"net": net}, {"opt": opt}, torch.device("cpu"))
        return opt.param_groups[0]["lr"]

    def train(name, lr_end, steps):
        config = tmp_path / f"{name}.yaml"
        config.write_text(f"width: 8\nlr: 0.002\nlr_end: {lr_end}\ndata:\n  views_per_material: 4\n")
        base = ["train", "mask", "--shapes", str(shapes_dir), "--out", str(tmp_path / name), "--config", str(config)]
        base += ["--samples", "12", "--resolution", "32", "--batch", "4", "--device", "cpu", "--iters", "6"]
        for count in steps:
            assert main(base[:-1] + [str(count)] + (["--resume"] if count != steps[0] else [])) == 0

    train("cosine", 0.1, [6])
    train("halves", 0.1, [3, 6])
    train("constant", 1.0, [6])
    assert last_rate(tmp_path / "cosine") == pytest.approx(0.0002)
    assert last_rate(tmp_path / "halves") == pytest.approx(0.0002)
    assert last_rate(tmp_path / "constant") == pytest.approx(0.002)


# ---------------------------------------------------------------------------- GAN-textured views
def _tiny_shapes(tiny_gan):
    from mesh2tex.geometry.prepared import load_shapes

    return load_shapes(tiny_gan / "shapes")[0]


def test_gan_colours_follow_the_rendered_vertex_order(tiny_gan):
    from mesh2tex.train.view_nets import _GanTextures

    from mesh2tex.nn.batch import collate_shapes

    shapes = _tiny_shapes(tiny_gan)
    gan = _GanTextures(str(tiny_gan / "run" / "checkpoint.safetensors"), shapes)
    for index, shape in enumerate(shapes):
        batch = collate_shapes([shape])
        assert np.array_equal(batch.shape_vertices(0).numpy(), shape.vertices[0])
        assert np.array_equal(batch.shape_triangles(0).numpy(), shape.triangles(0))
        colours = gan.vertex_colours(index, 3)
        assert colours.shape == (len(shape.vertices[0]), 3) and colours.dtype == np.float32
        assert 0 <= colours.min() and colours.max() <= 1
        assert np.array_equal(colours, gan.vertex_colours(index, 3)), "deterministic for a latent seed"


def test_train_with_gan_mixes_gan_and_procedural_views(tiny_gan, tmp_path, capsys):
    run = tmp_path / "pose"
    config = tmp_path / "c.yaml"
    config.write_text("width: 4\ndata:\n  views_per_material: 2\n  gan_share: 0.5\n")
    assert (
        main(
            [
                "train",
                "pose",
                "--shapes",
                str(tiny_gan / "shapes"),
                "--out",
                str(run),
                "--config",
                str(config),
                "--samples",
                "16",
                "--resolution",
                "16",
                "--batch",
                "4",
                "--iters",
                "1",
                "--device",
                "cpu",
                "--checkpoint",
                str(tiny_gan / "run" / "checkpoint.safetensors"),
            ]
        )
        == 0
    )
    assert (run / "checkpoint.safetensors").is_file()
    with np.load(run / "views.npz", allow_pickle=False) as views:
        gan_textured = views["gan_textured"]
        assert gan_textured.dtype == np.uint8 and gan_textured.shape == (16,) and set(gan_textured) == {0, 1}
        assert (views["mask"] > 127).any(axis=(1, 2)).all()
        # a group (2 views) shares its texture source
        assert (gan_textured[0::2] == gan_textured[1::2]).all()
    assert (
        main(
            [
                "train",
                "noc",
                "--shapes",
                str(tiny_gan / "shapes"),
                "--out",
                str(tmp_path / "noc"),
                "--checkpoint",
                str(run / "checkpoint.safetensors"),
            ]
        )
        == 2
    ), "a pose checkpoint is no GAN"
    assert (
        f"{run / 'checkpoint.safetensors'}: this is a 'pose' checkpoint, --checkpoint needs a 'gan' checkpoint"
        in capsys.readouterr().err
    )


def test_bad_gan_checkpoint_is_a_one_line_error(tiny_gan, shapes_dir, tmp_path, capsys):
    base = [
        "train",
        "noc",
        "--shapes",
        str(tiny_gan / "shapes"),
        "--samples",
        "4",
        "--resolution",
        "16",
        "--iters",
        "1",
        "--device",
        "cpu",
    ]
    missing = tmp_path / "missing.safetensors"
    assert main(base + ["--out", str(tmp_path / "a"), "--checkpoint", str(missing)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"mesh2tex: error: {missing}: checkpoint not found"
    assert not (tmp_path / "a").exists(), "nothing is written before the checkpoint is checked"
    not_a_checkpoint = tiny_gan / "shapes" / "box0.npz"
    assert main(base + ["--out", str(tmp_path / "b"), "--checkpoint", str(not_a_checkpoint)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{not_a_checkpoint}: not a mesh2tex checkpoint" in err
    # a GAN whose hierarchy differs from the shapes' (2 levels here, 3 in the GAN)
    gan = tiny_gan / "run" / "checkpoint.safetensors"
    base[base.index("--shapes") + 1] = str(shapes_dir)
    assert main(base + ["--out", str(tmp_path / "c"), "--checkpoint", str(gan)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{gan}: the prepared shapes have 2 levels, the generator needs 3" in err


def test_cached_views_are_rendered_again_when_the_data_settings_change(tiny_gan, tmp_path, monkeypatch):
    from mesh2tex.train import view_nets
    from mesh2tex.train.runs import RunDirectory

    calls = []
    render = view_nets.render_view_dataset
    monkeypatch.setattr(view_nets, "render_view_dataset", lambda *a: calls.append(1) or render(*a))
    run = RunDirectory(tmp_path / "run")
    shapes = _tiny_shapes(tiny_gan)
    cfg = view_nets.ViewTrainConfig(
        data=ViewDataConfig(
            samples=8,
            views_per_material=2,
            resolution=16,
            gan_share=0.5,
            gan_checkpoint=str(tiny_gan / "run" / "checkpoint.safetensors"),
        )
    )
    first = view_nets.load_or_render_views(run, shapes, cfg)
    again = view_nets.load_or_render_views(run, shapes, cfg)
    assert len(calls) == 1 and all(np.array_equal(first[k], again[k]) for k in first), (
        "the same settings reuse the cache"
    )
    cfg.data.gan_share = 1.0
    assert view_nets.load_or_render_views(run, shapes, cfg)["gan_textured"].all() and len(calls) == 2
    cfg.data.gan_checkpoint = ""
    assert not view_nets.load_or_render_views(run, shapes, cfg)["gan_textured"].any() and len(calls) == 3
    with np.load(run.root / "views.npz", allow_pickle=False) as cached:
        assert not cached["gan_textured"].any()


@pytest.mark.parametrize("kind", ["pose", "noc"])
def test_a_run_starts_from_another_runs_checkpoint(kind, shapes_dir, tmp_path, capsys):
    """``--resume PATH`` into a new --out reaches the weights of the source run continued in place; another kind is
    refused."""
    from mesh2tex.io.checkpoint import load_checkpoint

    config = tmp_path / "c.yaml"
    config.write_text("width: 8\nlog_every: 1\ndata:\n  views_per_material: 4\n")

    def train(out, *extra):
        return main(
            [
                "train",
                kind,
                "--shapes",
                str(shapes_dir),
                "--out",
                str(out),
                "--config",
                str(config),
                "--samples",
                "12",
                "--resolution",
                "32",
                "--batch",
                "4",
                "--device",
                "cpu",
                *extra,
            ]
        )

    source, other = tmp_path / "source", tmp_path / "other"
    assert train(source, "--iters", "2") == 0
    capsys.readouterr()
    assert train(other, "--iters", "4", "--resume", str(source / "checkpoint.safetensors")) == 0
    assert f"{other} starts from" in capsys.readouterr().err
    assert train(source, "--iters", "4", "--resume") == 0
    a, _ = load_checkpoint(source / "checkpoint.safetensors", kind=kind)
    b, meta = load_checkpoint(other / "checkpoint.safetensors", kind=kind)
    assert meta["iteration"] == 4
    assert [json.loads(line)["iteration"] for line in (other / "metrics.jsonl").read_text().splitlines()] == [3, 4]
    for name, tensor in a["net"].items():
        torch.testing.assert_close(tensor, b["net"][name], rtol=1e-5, atol=1e-6)
    wrong = "noc" if kind == "pose" else "pose"
    capsys.readouterr()
    assert (
        main(["train", wrong, "--shapes", str(shapes_dir), "--out", str(tmp_path / "wrong"), "--resume", str(source)])
        == 2
    )
    assert f"this is a '{kind}' checkpoint, expected a '{wrong}' training checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "wrong").exists()


def test_logged_numbers_go_to_tensorboard_as_well_when_it_is_there(tiny_gan, tmp_path, monkeypatch):
    """Every number of metrics.jsonl reaches TensorBoard (tag = key, step = iteration) when a writer
    is available; MESH2TEX_TENSORBOARD=0 turns it off."""
    from mesh2tex.train import runs

    class Recorder:
        def __init__(self):
            self.scalars = []

        def add_scalar(self, tag, value, step):
            self.scalars.append((tag, value, step))

        def flush(self):
            pass

    writers = []
    monkeypatch.setattr(runs, "tensorboard_writer", lambda folder: writers.append(Recorder()) or writers[-1])
    run = tmp_path / "noc"
    assert (
        main(
            [
                "train",
                "noc",
                "--shapes",
                str(tiny_gan / "shapes"),
                "--out",
                str(run),
                "--config",
                str(_tiny_config(tmp_path)),
                "--samples",
                "8",
                "--resolution",
                "16",
                "--batch",
                "4",
                "--iters",
                "2",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    # "time" is metrics.jsonl's own stamp; TensorBoard keeps its own wall time.
    expected = [
        (k, v, r["iteration"])
        for r in records
        for k, v in r.items()
        if k not in ("iteration", "time") and isinstance(v, (int, float))
    ]
    assert len(writers) == 1 and sorted(writers[0].scalars) == sorted(expected)
    monkeypatch.undo()  # the real writer again, with the variable set: none is made
    monkeypatch.setenv("MESH2TEX_TENSORBOARD", "0")
    assert runs.tensorboard_writer(tmp_path / "tb") is None


def _tiny_config(tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text("width: 4\n")
    return config
