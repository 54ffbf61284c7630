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
from mesh2tex.evaluation.report import BASELINES, PROTOCOLS
from mesh2tex.evaluation.world import load_world, photo_frame_view
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
    assert (
        main(
            [
                "train",
                "gan",
                "--shapes",
                str(shapes),
                "--images",
                str(world),
                "--out",
                str(root / "gan"),
                "--config",
                str(root / "tiny.yaml"),
                "--iters",
                "2",
                "--batch",
                "2",
                "--views",
                "1",
                "--resolution",
                "16",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    (root / "view.yaml").write_text("width: 4\ndata:\n  views_per_material: 4\n")
    for kind in ("pose", "noc"):
        assert (
            main(
                [
                    "train",
                    kind,
                    "--shapes",
                    str(shapes),
                    "--out",
                    str(root / kind),
                    "--config",
                    str(root / "view.yaml"),
                    "--iters",
                    "2",
                    "--samples",
                    "8",
                    "--resolution",
                    "32",
                    "--batch",
                    "4",
                    "--device",
                    "cpu",
                ]
            )
            == 0
        )
    protocol_yaml(root / "protocols.yaml")
    return root, index


def protocol_args(root, out, *extra):
    return [
        "evaluate",
        "--protocols",
        "--world",
        str(root / "world"),
        "--shapes",
        str(root / "shapes"),
        "--checkpoint",
        str(root / "gan" / "checkpoint.safetensors"),
        "--pose-checkpoint",
        str(root / "pose" / "checkpoint.safetensors"),
        "--noc-checkpoint",
        str(root / "noc" / "checkpoint.safetensors"),
        "--out",
        str(out),
        "--latent-iters",
        "2",
        "--refine-iters",
        "1",
        "--kid-subsets",
        "2",
        "--device",
        "cpu",
        "--config",
        str(root / "protocols.yaml"),
        *extra,
    ]


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
                assert (
                    np.isfinite(method["query"][f"{side} part_delta_e"])
                    and method["query"][f"{side} part_delta_e"] >= 0
                )
                assert np.isfinite(method["query"][f"{side} swd"])
                assert (f"{side} lowpass_psnr" in method["query"]) == exact and (
                    f"{side} psnr" in method["query"]
                ) == exact
        # The ground truth wins every column on exact geometry: a metric it loses is broken.
        if exact:
            assert entry["oracle_loses"] == [], f"{protocol}: the oracle loses {entry['oracle_loses']}"
        targets = {q["shape"] for q in entry["queries"]}
        assert targets == ({held_out} if protocol != "other_shape" else {index["split"]["train_shapes"][0]})
        assert set(result["comparison"][protocol]) == set(BASELINES) | {
            "no_noc",
            "no_patches",
            "no_refine",
            "no_mirror",
            "paper",
        }
    # The known pose is the sidecar's; stage 2 ran for the full method and not for no_refine.
    assert all(
        q["azimuth_error"] == 0 and q["elevation_error"] == 0 for q in result["protocols"]["known_pose"]["queries"]
    )
    # A found pose is judged up to the photographed shape's own symmetries too, never worse than plainly.
    for protocol, entry in result["protocols"].items():
        for q in entry.get("queries", []):
            if protocol == "known_pose":
                assert "symmetric_azimuth_error" not in q
            else:
                assert q["symmetries"] >= 1 and q["symmetric_azimuth_error"] <= q["azimuth_error"] + 1e-6
    rows = result["protocols"]["known_pose"]["methods"]
    assert (
        "refine" in rows["full"]["per_query"][0]["loss_last"]
        and "refine" not in rows["no_refine"]["per_query"][0]["loss_last"]
    )

    table = (out / "protocols.md").read_text()
    for title in (
        "| w/o NOC |",
        "| w/o patches |",
        "| w/o surface features (no refine) |",
        "| full method |",
        "| ground-truth texture (oracle) |",
        "| flat mean colour of the photo |",
        "| photo back-projection |",
        "| generator's mean texture (w_avg) |",
        "exact geometry, unknown pose",
        "transfer to another shape",
        "seen per-part ΔE ↓",
        "unseen low-pass PSNR ↑",
        "seen object SWD ↓",
    ):
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
    config = protocol_yaml(
        tmp_path / "automaton.yaml",
        transfer={"automaton": {"iters": 3, "steps_min": 2, "steps_max": 3, "final_steps": 2}},
    )
    out = tmp_path / "eval"
    args = protocol_args(
        root, out, "--only", "known_pose", "--ablations", "full", "--baselines", "oracle,flat_colour,automaton"
    )
    args[args.index("--config") + 1] = str(config)
    assert main(args) == 0
    entry = json.loads((out / "protocols.json").read_text())["protocols"]["known_pose"]
    assert list(entry["methods"]) == ["oracle", "flat_colour", "automaton", "full"]
    automaton = entry["methods"]["automaton"]
    assert len(automaton["per_query"]) == 2 and np.isfinite(automaton["query"]["seen part_delta_e"])
    assert np.isfinite(automaton["per_query"][0]["loss_last"])
    assert "| automaton fitted to the photo (no GAN) |" in (out / "protocols.md").read_text()
    plain, tuned = (
        config_from_dict(ProtocolConfig, d)
        for d in ({}, {"transfer": {"automaton": {"iters": 7}, "texture_format": "webp"}})
    )
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

    judged_apart = protocol_args(
        root,
        out,
        "--only",
        "known_pose",
        "--ablations",
        "full",
        "--config",
        str(protocol_yaml(tmp_path / "albedo.yaml", lighting="albedo", unseen_views=2)),
        "--overwrite",
    )
    assert main(judged_apart) == 0
    assert len(counted) == 3, (
        "judging with other lighting and views re-judges the kept transfers, it does not redo them"
    )


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


def protocol_yaml(path, transfer=None, **fields):
    path.write_text(
        yaml.safe_dump(
            {
                "latents": 1,
                "views": 2,
                "resolution": 32,
                **fields,
                "transfer": {"patch_size": 16, "scales": 1, **(transfer or {})},
            }
        )
    )
    return path
