"""The demo's report (``DIR/report.html``): the photo, the predicted pose and NOC, the renders, the
turntable, the transfer's and the generator's figures against the world's ground truth, timings.
Self-contained: every image is embedded as a data URI."""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

from mesh2tex.evaluation import METRIC_TITLES, METRICS
from mesh2tex.io.atomic import write_text
from mesh2tex.models import models_root

TRANSFER_METHODS = {  # name -> title in the report; every method judged alike (mesh2tex.evaluation)
    "oracle": "ground-truth texture (oracle)",
    "transfer": "mesh2tex transfer",
    "flat_colour": "flat mean colour of the photo",
    "mean_texture": "generator's mean texture (w_avg)",
    "backprojection": "photo back-projection",
}


def image_tag(path: Path | None, width: int) -> str:
    """An <img> with the file embedded as a data URI, so that report.html shows it when moved or mailed
    alone; '' when there is no such file."""
    if path is None or not path.is_file():
        return ""
    kind = {".png": "image/png", ".gif": "image/gif", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}[path.suffix.lower()]
    return f'<img src="data:{kind};base64,{base64.b64encode(path.read_bytes()).decode("ascii")}" width="{width}">'


def transfer_section(scores: dict, out: Path | None = None) -> str:
    """The report's transfer tables: a row per method (the oracle first), a column per metric with
    its direction, the photo's view and the unseen views apart; the best method but the oracle in bold."""
    esc = html.escape
    settings = scores.get("settings", {})
    methods = [m for m in TRANSFER_METHODS if m in scores]
    tables = []
    for side, title in (
        ("seen", "the photo's view"),
        ("unseen", f"{max(len(settings.get('views', [])) - 1, 0)} views the photo does not show (mean)"),
    ):
        columns = [m for m in METRICS if f"{side} {m}" in scores.get("transfer", {})]
        best = {}
        for metric in columns:
            values = [
                scores[m][f"{side} {metric}"] for m in methods if m != "oracle" and f"{side} {metric}" in scores[m]
            ]
            best[metric] = (max if METRICS[metric] > 0 else min)(values) if values else None
        head = "<th>method</th>" + "".join(
            f"<th>{esc(METRIC_TITLES[m])}<br><small>{'higher' if METRICS[m] > 0 else 'lower'} is better</small></th>"
            for m in columns
        )
        body = ""
        for name in methods:
            cells = []
            for metric in columns:
                value = scores[name].get(f"{side} {metric}")
                text = "-" if value is None else f"{value:.4g}"
                cells.append(
                    f"<td><b>{text}</b></td>"
                    if name != "oracle" and value is not None and value == best[metric]
                    else f"<td>{text}</td>"
                )
            body += f"<tr><td>{esc(TRANSFER_METHODS[name])}</td>{''.join(cells)}</tr>"
        tables.append(f"<h3>{esc(title)}</h3><table><tr>{head}</tr>{body}</table>")
    return f"""<h2>Transfer quality: the result beside the ground truth and the simple baselines</h2>
<p>Every method is a textured mesh rendered by the same function with the photo's camera and background
(lighting: {esc(str(settings.get("lighting", "photo")))}), at the photo's view and at views it does not show, against
what the world photographs there, on the object pixels only. Per-part ΔE: CIELAB distance of each part's mean colour
(seat, back, leg ...), weighted by pixel count; low-pass PSNR after a Gaussian blur of σ =
{settings.get("lowpass_sigma_px", 3):g} px; object SWD: sliced Wasserstein distance of object patches (x1e3). The
oracle (the world's ground-truth texture) is the ceiling: a metric it does not win would be broken. Back-projection and
the transfer use the pose the tool found (az {settings.get("pose_used", ["?"])[0]:.0f}, el
{settings.get("pose_used", ["?", "?"])[1]:.0f}); the flat colour and back-projection are what a user could script in a
few lines.</p>
{"".join(tables)}
<p>rows: what the world photographs | oracle | transfer | flat colour | mean texture | back-projection; columns: the
photo's view, then the unseen views</p>
{image_tag(out / "transfer" / "comparison_views.png" if out else None, min(5 * 160, 960))}
"""


def generation_section(g: dict, fmt, table, out: Path) -> str:
    """The report's generation tables: the protocol's rows (the oracle the bar), gap closed, diversity, samples."""
    labels = {
        "trained": "trained generator (EMA)",
        "untrained": "untrained generator",
        "oracle": "oracle: the world's material sampler, a draw per view, photo lighting",
        "oracle_unlit": "the same draws, unlit",
        "ground_truth": "each shape's own ground-truth material, photo lighting",
        "training_materials": "the training chairs' own materials (a generator that reproduced them)",
    }
    rows = [
        (labels[r], fmt(g["rows"][r]["object_swd"]), fmt(g["rows"][r]["color_hist_tv"]), fmt(g["rows"][r]["swd"]))
        for r in ("oracle", "trained", "untrained", "oracle_unlit", "ground_truth", "training_materials")
    ]
    d = g["diversity"]
    diversity = [
        ("trained generator", fmt(d["trained"]["spread"]), fmt(d["trained"]["pairwise"])),
        ("untrained generator", fmt(d["untrained"]["spread"]), fmt(d["untrained"]["pairwise"])),
        (
            "world's material sampler (reference)",
            fmt(d["reference_materials"]["spread"]),
            fmt(d["reference_materials"]["pairwise"]),
        ),
        ("photo set, across shapes (reference)", fmt(d["photo_set_spread"]), ""),
    ]
    gap = g["gap_closed"]
    shipped = shipped_model_note(fmt)
    loses = g.get("oracle_loses", [])
    oracle_note = (
        f"<p>Columns the oracle does not win here: {', '.join(loses)}. On so few held-out chairs those figures rank "
        "runs, not the distance to the ground truth.</p>\n"
        if loses
        else ""
    )
    columns = (
        "renders",
        "object SWD (lower is better)",
        "colour histogram TV (lower is better)",
        "whole-image SWD (lower is better)",
    )
    return f"""<h2>Generation: the GAN on the {len(g["shapes"])} held-out shapes, against a fresh photo set</h2>
<p>Every distance is to a fresh photo set: the training shapes at their photos' cameras and lights, each photo with a
new material of the world's sampler. (Measured against the training photos themselves, a generator that reproduces their
few materials beats fresh draws of the true textures, and the oracle would no longer be the bar.)</p>
{table(rows, columns)}
<p>Gap closed (log object SWD; 0 = untrained, 1 = oracle; higher is better): <b>{fmt(gap)}</b>; a generator that
reproduced its training chairs' materials exactly would close {fmt(g.get("gap_closed_training_materials"))}.
Object SWD: sliced Wasserstein distance of 7x7 patches of object pixels only (x1e3); the whole-image SWD also sees the
white background and the silhouettes, which the rows share, so it barely ranks textures.</p>
{oracle_note}<p>Diversity: {g["settings"]["latents"]} latents per held-out shape at one pose (higher is more varied).
Colour spread {fmt(d["trained_spread_vs_photo_set"])} of the photo set's.</p>
{table(diversity, ("", "colour spread (ΔE)", "mean pairwise ΔE"))}
{shipped}
<p>Samples: rows latents, columns views; the last row is the ground truth.</p>
{image_tag(out / "gan" / "generation_samples.png", 384)}"""


def shipped_model_note(fmt) -> str:
    """A paragraph with the shipped chair model's figures (from its card), or '' when none is shipped."""
    card_path = models_root() / "chair" / "card.json"
    if not card_path.is_file():
        return ""
    card = json.loads(card_path.read_text())
    g = card["generation"]
    d = g["diversity"]
    return (
        f"<p>For comparison, the shipped <code>chair</code> model ({card['gan_iterations']} GAN iterations on "
        f"{card['world']['shapes'] - card['world']['query_shapes']} chairs, measured the same way on its own world's "
        f"{len(g['shapes'])} held-out chairs): gap closed <b>{fmt(g['gap_closed'])}</b>, colour spread "
        f"{fmt(d['trained_spread_vs_photo_set'])} of the photo set's (mesh2tex/models/chair/card.md).</p>"
    )


def write_report(out: Path, cfg, seconds: dict, query: dict, metrics: dict) -> Path:
    """DIR/report.html: the photo, predicted pose and NOC, renders, turntable, metrics and timings (``cfg``: the
    demo's :class:`~mesh2tex.infer.demo.DemoConfig`).

    Self-contained: every image is embedded (data URIs); only the links to the GLB, PLY and JSON files
    point next to it."""
    transfer = json.loads((out / "transfer" / "report.json").read_text())
    esc = html.escape

    def table(rows: list[tuple], header: tuple) -> str:
        head = "".join(f"<th>{esc(str(h))}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in row) + "</tr>" for row in rows)
        return f"<table><tr>{head}</tr>{body}</table>"

    def fmt(value) -> str:
        return f"{value:.4g}" if isinstance(value, float) else str(value)

    pose = transfer["pose"]
    pose_rows = [
        ("true (query sidecar)", fmt(query["azimuth"]), fmt(query["elevation"])),
        (f"used ({pose['source']})", fmt(pose["azimuth"]), fmt(pose["elevation"])),
    ]
    pose_note = ""
    if "network" in pose:  # the silhouette search ran: show what the network alone said, and both silhouette IoUs
        pose_rows.append(("pose network alone", fmt(pose["network"][0]), fmt(pose["network"][1])))
        pose_note = (
            f"<p>Silhouette IoU with the photo's mask: {fmt(pose['silhouette_iou'])} at the used pose, "
            f"{fmt(pose['network_silhouette_iou'])} at the network's.</p>"
        )
    generation = generation_section(metrics["generation"], fmt, table, out)
    time_rows = [(stage, f"{s:.0f}") for stage, s in seconds.items()]
    stage_rows = [(stage, fmt(float(v))) for stage, v in transfer["seconds"].items()]
    vgg = transfer.get("vgg", {})
    vgg_note = (
        ""
        if vgg.get("pretrained")
        else (
            "<p class=note>Style losses used a random-weight VGG19 (no ImageNet weights on this machine): expect "
            "less faithful detail. Pass <code>--vgg-weights</code> to <code>infer transfer</code> for the paper's "
            "features.</p>"
        )
    )
    body = f"""<!doctype html><html><head><meta charset="utf-8"><title>mesh2tex demo</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}}
img{{image-rendering:pixelated;border:1px solid #ccc;margin:2px}} table{{border-collapse:collapse;margin:0.5em 0}}
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}
.note{{color:#a40}}</style></head><body>
<h1>mesh2tex demo</h1>
<p>A held-out chair mesh (<code>{esc(query["shape"])}</code>, never seen in training) textured after a held-out query
photo (<code>{esc(query["image"])}</code>), with pose and NOC predicted by the networks trained here.
Budget: {cfg.gan.iters} GAN iterations, {cfg.transfer.latent_iters} + {cfg.transfer.refine_iters} transfer iterations
on the CPU (the paper: 50k GAN iterations on two GPUs, 100 + 300 transfer iterations).</p>
<h2>Query and result</h2>
<p>photo crop | render of the result at the used pose | predicted photo NOC | rendered mesh NOC</p>
{image_tag(out / "transfer" / "comparison.png", 4 * 192)}
<p>the exported GLB rendered at the query's true pose, and the turntable</p>
{image_tag(out / "transfer" / "render_at_true_pose.png", 192)} {image_tag(out / "transfer" / "turntable.gif", 256)}
<p>Files: <a href="transfer/textured.glb">textured.glb</a> (opens in Blender), <a
href="transfer/textured.ply">textured.ply</a>,
<a href="transfer/report.json">report.json</a>.</p>
{vgg_note}
<h2>Pose</h2>{table(pose_rows, ("", "azimuth", "elevation"))}{pose_note}
{transfer_section(metrics["transfer"], out)}
{generation}
<h2>Timings (seconds, each stage summed over every run of the demo in this
folder)</h2>{table(time_rows, ("stage", "seconds"))}
<h3>Transfer stages (seconds)</h3>{table(stage_rows, ("stage", "seconds"))}
</body></html>
"""
    path = out / "report.html"
    write_text(path, body)
    return path
