"""``n2r info SCENE``: what a scene file holds (views, split, field size, fit report, file size); of any other
scene ``--n2r-scene`` takes (``demo:<name>``, ``module:function``, a 3DGS ``.ply``), its views, cameras and scale."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, TypeGuard

from ._output import printable
from ._scene import SCENE_HELP

if TYPE_CHECKING:
    from ..demo.scene_specs import SceneSpec
    from ..scene.base import Scene
    from ..scene.field_scene import FieldScene
    from ..scene.file import SceneFile
    from ..study.fidelity import FidelityReport

__all__ = ["add_parser", "run", "format_info", "info_dict", "format_scene_info", "scene_info_dict", "format_splat_info"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "info", help="summarize a scene (a .n2r scene file, demo:<name>, ...)",
        description="Print what a scene file holds: views and split, cameras, scale, field size, and the fit "
                    "report (held-out PSNR/SSIM per view with how far each is from its nearest fitted view, the "
                    "training views' PSNR/SSIM, training time, device, versions); of a scene that is "
                    "no scene file (an exact demo scene, module:function, a 3DGS .ply), its views and split, "
                    "cameras and scale.",
    )
    p.add_argument("scene", metavar="SCENE", help=SCENE_HELP)
    p.add_argument("--json", action="store_true", help="print the summary as JSON instead")
    p.add_argument("--shift", action="store_true",
                   help="also measure the reality-to-field shift of ORB, SIFT and AKAZE (repeatability and spread, "
                        "stored photo vs render at each held-out pose; renders, so seconds to minutes; cached)")
    p.add_argument("--size", default="480", metavar="PX",
                   help="render size of --shift: the longer side in pixels or WxH (default: 480)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..render.size import RenderSize
    from ..scene.base import Scene
    from ..scene.splat_file import is_splat_file, splat_info
    from ._scene import scene_argument

    RenderSize.parse(args.size, name="--size")  # checked before the scene is read
    spec = scene_argument(args.scene)
    if spec.kind == "file" and is_splat_file(spec.source):  # splats packed by `n2r import`
        if args.shift:
            raise _no_photos(spec.source, "a splat scene file (n2r import packs the splats and their cameras, no "
                                          "photos)")
        info = splat_info(spec.source)
        print(printable(_json(info) if args.json else _readable(format_splat_info, info, spec.source)))
        return 0
    scene = _open(spec, images=args.shift)
    if isinstance(scene, Scene):  # no scene file: an exact demo scene, a 3DGS .ply ...
        if args.shift:
            raise _no_photos(spec.source, f"no fitted scene file (a {type(scene).__name__})")
        print(printable(_json(scene_info_dict(scene, spec)) if args.json else format_scene_info(scene, spec)))
        return 0
    shift = _shift(scene, args.size) if args.shift else None
    if args.json:
        print(printable(_json({**info_dict(scene), **({"shift": shift.to_dict()} if shift else {})})))
    else:
        print(printable(_readable(format_info, scene, scene.path) + (f"\n{shift.format()}" if shift else "")))
    return 0


def _readable(format_text: Callable[[Any], str], what: Any, path: str | os.PathLike) -> str:
    """``format_text(what)``; a report edited by hand, or written by another tool, is a
    :class:`~pytest_n2r.errors.SceneFileError` naming the scene file ``path``."""
    try:
        return format_text(what)
    except ReportUnreadable as exc:
        from ..errors import SceneFileError

        raise SceneFileError(f"{path}: scene.json {exc.args[0]} (not as n2r writes it); n2r info --json prints it "
                             "as stored") from exc


def _open(spec: SceneSpec, images: bool) -> SceneFile | Scene:
    """The fitted scene file behind ``spec`` (a .n2r file, ``demo:<name>-field``, a Python scene that is a
    fitted field), else the scene itself (``images``: decode a file's photos)."""
    if spec.kind == "file" and not spec.source.lower().endswith(".ply"):
        from ..scene.file import read_scene_file

        return read_scene_file(spec.source, images=images)
    from ..demo.scene_specs import load_scene_spec

    scene = load_scene_spec(spec, "cpu", images=images)
    return scene.file if _fitted(scene) else scene


def _fitted(scene: Scene) -> TypeGuard[FieldScene]:
    """Whether ``scene`` is a fitted field's, without importing its module: a scene of a class whose module is not
    imported is none of its instances (the fitted-scene modules import torch, about 1 s an exact scene need not pay)."""
    loaded = sys.modules.get("pytest_n2r.scene.field_scene")
    return loaded is not None and isinstance(scene, loaded.FieldScene)


def _json(data: dict) -> str:
    """``data`` as strict JSON (what any JSON reader reads): a number that is not finite is ``null``."""
    from ..scene.schema import json_ready

    return json.dumps(json_ready(data), indent=2, allow_nan=False)


def _no_photos(source: str, what: str) -> Exception:
    """The refusal of ``--shift`` for a scene ``source`` that is ``what`` and holds no photos."""
    from ..errors import InvalidArgument

    return InvalidArgument(f"--shift is not supported for {source}: it is {what}, so it has no photos to compare its "
                           "renders with; measure the shift on the .n2r scene file of a fit")


def _shift(scene: SceneFile, size: str) -> FidelityReport:
    """The detector shift of the scene file (floors cached in the user cache folder)."""
    from ..demo.fitted import cache_dir
    from ..relation.floor import FloorStore
    from ..scene.field_scene import FieldScene
    from ..study.fidelity import measure_fidelity

    return measure_fidelity(FieldScene(scene, device="cpu"), size=size, store=FloorStore(cache_dir() / "floors"))


def info_dict(scene: SceneFile) -> dict:
    """The summary as plain JSON-ready values (sizes in bytes, lengths in scene units)."""
    splits = [v.split for v in scene.views]
    cameras = list(dict.fromkeys(v.camera for v in scene.views))
    tensors = scene.field.tensors()
    return {
        "path": str(scene.path),
        "file_bytes": scene.size_bytes,
        "format_version": scene.version,
        "views": len(scene.views),
        "train_views": splits.count("train"),
        "heldout_views": splits.count("heldout"),
        "photos_stored": scene.images_stored,
        "cameras": [c.to_dict() for c in cameras],
        "reference_length": scene.reference_length,
        "metres_per_unit": scene.metres_per_unit,
        "bounds": scene.bounds.tolist(),
        "field": {**scene.field.describe(),
                  "tensor_bytes": sum(t.numel() * t.element_size() for t in tensors.values()),
                  "memory_bytes": scene.field.memory_bytes()},
        "config": scene.config.to_dict(),
        "report": scene.report,
    }


def format_info(scene: SceneFile) -> str:
    """The plain-text summary ``n2r info`` (and ``n2r fit`` at the end) prints."""
    from ..fit.memory import byte_count

    info = info_dict(scene)
    report, field = info["report"], info["field"]
    lines = [
        f"scene       {info['path']} ({byte_count(info['file_bytes'])}, format version {info['format_version']})",
        (f"views       {info['views']}: {info['train_views']} train, {info['heldout_views']} held out; "
         f"{info['photos_stored']} photos stored"),
    ]
    lines += _camera_and_scale_lines(info)
    lines.append(f"field       {field['resolution']}³ grid, SH degree {field['sh_degree']}, "
                 f"{100 * field['occupied_fraction']:.1f}% of cells occupied, {field['stored_vertices']} vertices "
                 f"stored ({byte_count(field['tensor_bytes'])}; {byte_count(field['memory_bytes'])} in memory)")
    return "\n".join(lines + _report_lines(report))


def scene_info_dict(scene: Scene, spec: SceneSpec) -> dict:
    """The summary of a scene with no fitted scene file behind it (an exact demo scene, a Python scene, a 3DGS
    ``.ply``) as plain JSON-ready values: where it comes from, its views and split, cameras and scale."""
    splits = [v.split for v in scene.views]
    return {
        "scene": spec.source,
        "name": scene.name,
        "kind": spec.kind,
        "type": type(scene).__name__,
        "exact": scene.is_exact,
        "views": len(scene.views),
        "train_views": splits.count("train"),
        "heldout_views": splits.count("heldout"),
        "photos_stored": sum(v.image is not None for v in scene.views),
        "cameras": [c.to_dict() for c in dict.fromkeys(v.camera for v in scene.views)],
        "reference_length": scene.reference_length if scene.views else None,  # it is measured on the cameras
        "metres_per_unit": scene.metres_per_unit,
    }


def format_scene_info(scene: Scene, spec: SceneSpec) -> str:
    """The plain-text summary ``n2r info`` prints of a scene with no fitted scene file behind it."""
    info = scene_info_dict(scene, spec)
    renders = "exact renders (the ground truth at any pose)" if info["exact"] else "renders not exact"
    views = (f"views       {info['views']}: {info['train_views']} train, {info['heldout_views']} held out; "
             f"{info['photos_stored']} photos stored")
    if not scene.views and scene.no_views_reason:
        views += f" ({scene.no_views_reason})"
    notes = [f"  note      {note}" for note in getattr(scene, "notes", ())]  # what a splat loader converted
    return "\n".join([f"scene       {spec.source}: {info['type']} {info['name']!r}, {renders}", views,
                      *_camera_and_scale_lines(info), *notes])


def format_splat_info(info: dict) -> str:
    """The plain-text summary ``n2r info`` prints of a splat scene file (``info`` as
    :func:`~pytest_n2r.scene.splat_file.splat_info` reads it; bounds in scene units)."""
    from ..fit.memory import byte_count

    splats, (low, high) = info["splats"], info["bounds"]
    background = ", ".join(f"{c:g}" for c in splats["background"])
    extent = ", ".join(f"{axis} {a:.4g} to {b:.4g}" for axis, a, b in zip("xyz", low, high, strict=True))
    lines = [f"scene       {info['path']} ({byte_count(info['file_bytes'])}, 3-D Gaussian splats)",
             (f"views       {info['views']}: {info['train_views']} train, {info['heldout_views']} held out; "
              "no photos stored"),
             *_camera_and_scale_lines(info),
             f"splats      {splats['count']} Gaussians, SH degree {splats['sh_degree']}, background ({background})",
             f"bounds      {extent} scene units (the Gaussians the views see)"]
    with _reading("'source', 'source_sha256', 'cameras', 'from_field', 'imported_by' or 'import_s'"):
        report = info["report"]
        if "source" in report:
            digest = f" (sha256 {report['source_sha256'][:12]}…)" if "source_sha256" in report else ""
            lines.append(f"  source    {report['source']}{digest}")
        if "cameras" in report:
            lines.append(f"  cameras   {report['cameras']}")
        lines += [f"  note      {note}" for note in report.get("notes", ())]
        made = report.get("from_field")
        if made:
            psnr = made.get("fit", {}).get("psnr")
            lines += [f"  from      a {made['resolution']}³ field" + (f" ({psnr:.2f} dB held out)" if psnr else ""),
                      (f"            one Gaussian a voxel: σ {made['size']:g} voxel sides, peak opacity for "
                       f"{made['path']:g} voxels of density (--size, --path)")]
        if "imported_by" in report:
            seconds = f" in {report['import_s']:.1f} s" if "import_s" in report else ""
            lines.append(f"  imported  by {report['imported_by']}{seconds}")
    return "\n".join(lines)


def _camera_and_scale_lines(info: dict) -> list[str]:
    """The cameras (the first three) and the scale of a summary."""
    lines = [f"  camera    {cam['width']}x{cam['height']} fx={cam['fx']:.2f} fy={cam['fy']:.2f} cx={cam['cx']:.2f} "
             f"cy={cam['cy']:.2f}" for cam in info["cameras"][:3]]
    if len(info["cameras"]) > 3:
        lines.append(f"  ... and {len(info['cameras']) - 3} more cameras")
    mpu, length = info["metres_per_unit"], info["reference_length"]
    lines.append("scale       " + (f"reference length {length:.4g} scene units; " if length is not None else
                                   "no reference length (no cameras); ")
                 + (f"{mpu:.4g} m per scene unit" if mpu is not None else "metric scale unknown"))
    return lines


class ReportUnreadable(ValueError):
    """A value of a scene file's ``report`` that :func:`format_info` cannot read: ``keys`` names the report's keys
    being read (a report is free-form JSON that any tool may have written); ``n2r info`` turns it into a
    :class:`~pytest_n2r.errors.SceneFileError` naming the file."""

    def __init__(self, keys: str, cause: Exception):
        super().__init__(f"report {keys}: {type(cause).__name__}: {cause}")
        self.keys = keys


@contextlib.contextmanager
def _reading(keys: str) -> Iterator[None]:
    try:
        yield
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:  # OverflowError: 10**400
        raise ReportUnreadable(keys, exc) from exc


def _report_lines(report: dict) -> list[str]:
    """The fit report's lines of :func:`format_info` (:class:`ReportUnreadable` where a value is not as ``n2r fit``
    writes it)."""
    from ..fit.memory import GridChoice
    from .poses import format_skipped

    lines = []
    with _reading("'detail'"):
        detail = report.get("detail")
        if detail:
            lines.append(f"  detail    a voxel spans {detail['pixels_per_voxel']:.1f} training pixels where the "
                         f"cameras look closest (a {detail['matching_resolution']}³ grid would match the photos)")
            if detail.get("grid_added"):
                lines.append(f"            {detail['grid_added']}³ added for the end of the fit: the ladder's grids "
                             "were coarser than the photos (FieldConfig.max_pixels_per_voxel)")
    with _reading("'grid_limits'"):
        for limit in report.get("grid_limits") or []:
            choice = GridChoice(limit["wanted"], limit["trained"], limit["needed_bytes"], limit["free_bytes"])
            lines.append(f"  memory    at step {limit['step']}, {choice.message()}")
    with _reading("'complete', 'stopped', 'steps', 'train_seconds', 'compile_seconds', 'device' or 'threads'"):
        state = ("checkpoint (the fit did not finish)" if not report.get("complete", True)
                 else "stopped before the end of its budget" if report.get("stopped") else "complete")
        where = f" on {report['device']}" if "device" in report else ""
        threads = f" ({report['threads']} threads)" if "threads" in report else ""
        # a fitted demo scene stores no timings (its file is rebuilt byte for byte)
        seconds = report.get("train_seconds")
        duration = f"{seconds:.1f} s of training" if seconds is not None else "training time not recorded"
        compiling = report.get("compile_seconds") or 0.0  # a fresh installation's first fit compiles its kernels
        duration += f" (and {compiling:.1f} s compiling its kernels)" if compiling >= 0.05 else ""
        lines.append(f"fit         {state}: {report.get('steps', '?')} steps, {duration}{where}{threads}")
    with _reading("'source' or 'downscale'"):
        if "source" in report:
            lines.append(f"  source    {report['source']} (downscale {report.get('downscale', 1):g})")
    with _reading("'skipped' or 'warnings'"):  # the photos of the capture the fit did not use, and why
        lines += format_skipped([(r["file"], r["reason"]) for r in report.get("skipped") or []])
        lines += [f"  warning   {w}" for w in report.get("warnings") or []]
    with _reading("'heldout', 'psnr', 'ssim', 'nearest_fitted', 'train_psnr', 'train_ssim' or 'train_scored'"):
        lines += _score_lines(report)
    with _reading("'exposure'"):
        exposure = report.get("exposure")
        if exposure:
            lines.append(format_exposure(exposure))
    with _reading("'appearance'"):
        gains = report.get("appearance")
        if gains:
            values = [g for rgb in gains.values() for g in rgb]
            lines.append(f"appearance  a colour gain per training photo ({len(gains)} photos, {min(values):.3f} to "
                         f"{max(values):.3f}); renders use none")
    with _reading("'history'"):
        for entry in report.get("history") or []:
            scores = (f"PSNR {entry['psnr']:.2f} dB, SSIM {entry['ssim']:.4f}" if entry.get("psnr") is not None
                      else "no held-out view with a photo")
            lines.append(f"  after {entry['seconds']:g} s of training (step {entry['step']}): {scores}")
    with _reading("'versions'"):
        versions = report.get("versions")
        if versions:
            lines.append("versions    " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    return lines


def _score_lines(report: dict) -> list[str]:
    """The held-out views' scores (PSNR in dB), how far they are from the fitted views (``nearest_fitted``: degrees
    between optical axes, distance between centres in reference lengths) and the training views' scores
    (``train_psnr``); older reports hold neither of the last two, and their lines are left out."""
    lines, rows, near = [], report.get("heldout") or [], report.get("nearest_fitted")
    if report.get("psnr") is not None:
        lines.append(f"held out    PSNR {report['psnr']:.2f} dB, SSIM {report['ssim']:.4f} (mean of {len(rows)} views)")
        if near:
            deg, dist = near["degrees"], near["distance"]
            lines.append(f"  nearest   fitted view {deg['median']:.1f}° and {dist['median']:.3f} reference lengths "
                         f"away (median; least {deg['min']:.1f}° and {dist['min']:.3f}): how new the poses are")
        width = max(len(r["view"]) for r in rows)
        lines.append(f"  {'view':<{width}}  PSNR dB    SSIM" + ("  nearest fitted view" if near else ""))
        lines += [f"  {r['view']:<{width}}  {_num(r['psnr'], 7, 2)}  {_num(r['ssim'], 6, 4)}"
                  + (f"  {r['nearest_degrees']:5.1f}°  {r['nearest_distance']:.3f} ref. lengths  {r['nearest']}"
                     if near else "") for r in rows]
    elif report.get("complete", True):
        lines.append("held out    no held-out view with a photo (nothing to score)")
    if report.get("train_psnr") is not None:
        lines.append(f"training    PSNR {report['train_psnr']:.2f} dB, SSIM {report['train_ssim']:.4f} (mean of "
                     f"{len(report['train_scored'])} training views along the capture, scored as the held-out ones)")
    return lines


def format_exposure(exposure: dict) -> str:
    """The line saying how much a capture's photos differ in exposure and white balance and whether the fit
    corrected it (a fit's ``report["exposure"]``, :func:`pytest_n2r.fit.appearance.measured_appearance`)."""
    if exposure["jump"] is None:
        measured = "not measured (no two photos linked by matches)"
    else:
        measured = (f"neighbouring photos' colours differ by {100 * exposure['jump']:.1f} % (median of "
                    f"{exposure['pairs']} pairs; {exposure['photos']} of {exposure['of']} photos measured), the "
                    f"whole capture's by {100 * exposure['spread']:.1f} %")
    return (f"exposure    {measured}: per-photo correction {'on' if exposure['appearance'] else 'off'} "
            f"(auto: on above {100 * exposure['threshold']:g} % between neighbours)")


def _num(value: float | None, width: int, digits: int) -> str:
    return f"{value:{width}.{digits}f}" if value is not None else f"{'inf':>{width}}"
