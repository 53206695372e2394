"""The bad-input catalogue of the ``n2r`` commands and of scene files (docs/reliability.md counts it).

One line per case: the input a tired user (or a hostile file) gives → the message expected. Every command
case asserts a non-zero exit code, no traceback (nothing escapes ``main``), a message naming the thing and
the fix, and that no file in the workspace changed (every byte of every file compared).
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import tracemalloc
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from PIL import Image

from pytest_n2r.cli.main import main
from pytest_n2r.errors import SceneFileError
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.scene import read_scene_file, save_scene
from pytest_n2r.scene.file import check_scene_file
from pytest_n2r.scene.schema import FIELD_FILE, SCENE_JSON

from ..data.synthetic import make_capture, write_transforms
from .conftest import random_field, tiny_views
from .test_file import rewrite

#: (id, command line with {placeholders} of the workspace, regex the error message must match)
COMMAND_CASES: list[tuple[str, str, str]] = [
    # -- the command line itself
    ("unknown command", "frobnicate", r"invalid choice: 'frobnicate'"),
    ("demo without an action", "demo", r"the following arguments are required: ACTION"),
    # -- n2r fit: outputs
    ("fit over its own transforms.json", "fit {capture}/transforms.json -o {capture}/transforms.json",
     r"-o .*transforms.json: expected a \.n2r scene file, a name ending in \.n2r \(e\.g\. transforms\.n2r\)"),
    ("fit over a text file", "fit {capture} -o {notes_txt}",
     r"expected a \.n2r scene file, a name ending in \.n2r"),
    ("fit over a .n2r that is no scene", "fit {capture} -o {fake_n2r}",
     (r"fake\.n2r: exists and is not a \.n2r scene file, so writing would destroy it; choose another nam"
      r"e, or pass --force")),
    ("fit over a zip needing version 9.1", "fit {capture} -o {zip91_n2r}",
     r"zip91\.n2r: exists and is not a \.n2r scene file, so writing would destroy it"),
    ("fit over its own input scene", "fit {scene} -o {scene}",
     r"is this command's input .*; writing there would destroy it"),
    ("fit into a folder", "fit {capture} -o {capture}",
     r"is a folder; expected the path of a \.n2r scene file"),
    ("fit into a file's 'folder'", "fit {capture} -o {notes_txt}/x.n2r",
     r"notes\.txt is a file, not a folder"),
    ("fit into a read-only folder", "fit {capture} -o /proc/x.n2r", r"cannot write into /proc"),
    ("fit without -o", "fit {capture}", r"the following arguments are required: -o/--output"),
    ("fit --frames-dir is a file", "fit {capture} -o {new_n2r} --frames-dir {notes_txt}",
     r"--frames-dir .*notes\.txt: is a file; expected a folder for the video's frames"),
    # -- n2r fit: every number before any work
    ("fit --metres-per-unit -1", "fit {capture} -o {new_n2r} --metres-per-unit -1",
     r"--metres-per-unit -1\.0: expected the finite number of metres per scene unit, > 0"),
    ("fit --metres-per-unit 0", "fit {capture} -o {new_n2r} --metres-per-unit 0", r"--metres-per-unit 0\.0"),
    ("fit --metres-per-unit nan", "fit {capture} -o {new_n2r} --metres-per-unit nan",
     r"--metres-per-unit nan"),
    ("fit --metres-per-unit inf", "fit {capture} -o {new_n2r} --metres-per-unit inf",
     r"--metres-per-unit inf"),
    ("fit --metres-per-unit one", "fit {capture} -o {new_n2r} --metres-per-unit one",
     r"argument --metres-per-unit: invalid float value: 'one'"),
    ("fit --downscale 0.5", "fit {capture} -o {new_n2r} --downscale 0.5",
     r"--downscale 0\.5: expected a finite factor >= 1"),
    ("fit --downscale nan", "fit {capture} -o {new_n2r} --downscale nan",
     r"--downscale nan: expected a finite"),
    ("fit --downscale 1000", "fit {corner} -o {new_n2r} --downscale 1000 --max-steps 2",
     (r"--downscale 1000: the photo 'images/view_000\.png' would be 1x1 pixels; expected views of at least 11 pixel"
      r"s a side")),
    ("fit --max-steps 0", "fit {capture} -o {new_n2r} --max-steps 0",
     r"--max-steps 0: expected an integer >= 1"),
    ("fit --max-steps 1.5", "fit {capture} -o {new_n2r} --max-steps 1.5", r"invalid int value: '1\.5'"),
    ("fit --time-budget 0", "fit {capture} -o {new_n2r} --time-budget 0", r"'0': expected a duration > 0"),
    ("fit --time-budget ten", "fit {capture} -o {new_n2r} --time-budget ten",
     r"'ten' is not a duration; expected e\.g\. 10m, 90s, 1h30m"),
    ("fit --time-budget -5m", "fit {capture} -o {new_n2r} --time-budget=-5m", r"'-5m' is not a duration"),
    ("fit --checkpoint-every 0", "fit {capture} -o {new_n2r} --checkpoint-every 0",
     r"--checkpoint-every 0\.0: expected a finite number of seconds > 0"),
    ("fit --checkpoint-every inf", "fit {capture} -o {new_n2r} --checkpoint-every inf",
     r"--checkpoint-every inf"),
    ("fit --appearance maybe", "fit {capture} -o {new_n2r} --appearance maybe",
     r"argument --appearance: invalid choice: 'maybe'"),
    ("fit --eval-at 1m,,3m", "fit {capture} -o {new_n2r} --eval-at 1m,,3m", r"'' is not a duration"),
    ("fit --device tpu", "fit {capture} -o {new_n2r} --device tpu",
     r"device='tpu': expected 'auto', 'cpu' or 'cuda\[:N\]'"),
    ("fit SOURCE missing", "fit {tmp}/nowhere -o {new_n2r}",
     r"SOURCE .*nowhere: does not exist; expected a transforms\.json"),
    # -- n2r fit --config
    ("--config resolutions=abc", "fit {capture} -o {new_n2r} --config resolutions=abc",
     r"--config 'resolutions=abc': 'abc' is not a number, True/False or a comma-separated list"),
    ("--config resolutions='abc'", "fit {capture} -o {new_n2r} --config \"resolutions='abc'\"",
     r"--config: FieldConfig\.resolutions=\('abc',\): expected a list of integers \(default: 32,96,224\)"),
    ("--config seed='x'", "fit {capture} -o {new_n2r} --config \"seed='x'\"",
     r"FieldConfig\.seed='x': expected an integer \(default: 0\)"),
    ("--config seed=1.5", "fit {capture} -o {new_n2r} --config seed=1.5",
     r"FieldConfig\.seed=1\.5: expected an integer"),
    ("--config random_background=1", "fit {capture} -o {new_n2r} --config random_background=1",
     r"FieldConfig\.random_background=1: expected True or False"),
    ("--config tv=None", "fit {capture} -o {new_n2r} --config tv=None",
     r"FieldConfig\.tv=None: expected a number"),
    ("--config resolutions=4", "fit {capture} -o {new_n2r} --config resolutions=4",
     r"resolutions=\(4,\): expected increasing grid sizes in 8\.\.1024"),
    ("--config stage_fractions=2", "fit {capture} -o {new_n2r} --config stage_fractions=2",
     r"stage_fractions=\(2\.0,\): expected 2 increasing fractions in \(0, 1\)"),
    ("--config lr_density=-1", "fit {capture} -o {new_n2r} --config lr_density=-1",
     r"FieldConfig\.lr_density=-1: expected a finite number > 0"),
    ("--config warp=2", "fit {capture} -o {new_n2r} --config warp=2", r"unknown setting 'warp'; known: "),
    ("--config without =", "fit {capture} -o {new_n2r} --config seed",
     r"--config 'seed': expected key=value"),
    ("--config code", "fit {capture} -o {new_n2r} --config \"seed=__import__('os')\"",
     r"is not a number, True/False or a comma-separated list"),
    # -- n2r render: outputs, checked before loading and rendering
    ("render over its scene", "render {scene} -o {scene}",
     r"-o .*scene\.n2r: expected a PNG image, a name ending in \.png \(e\.g\. scene\.png\)"),
    ("render to .jpg", "render {scene} -o {tmp}/view.jpg", r"expected a PNG image, a name ending in \.png"),
    ("render over a text file named .png", "render {scene} -o {fake_png}",
     (r"fake\.png: exists and is not a PNG image, so writing would destroy it; choose another name, or p"
      r"ass --force")),
    ("render depth over a text file", "render {scene} --depth -o {tmp}/note.png",
     r"-o \(its depth file beside it\) .*note\.depth\.png: exists and is not a PNG image"),
    ("render opacity over a text file", "render {scene} --opacity -o {tmp}/note.png",
     r"-o \(its opacity file beside it\) .*note\.opacity\.png: exists and is not a PNG image"),
    ("render into a folder", "render {scene} -o {capture}", r"is a folder; expected the path of a PNG image"),
    ("render to /", "render {scene} -o /", r"-o /: is a folder"),
    ("render into a read-only folder", "render {scene} -o /proc/view.png", r"cannot write into /proc"),
    ("render into a file's 'folder'", "render {scene} -o {notes_txt}/view.png",
     r"notes\.txt is a file, not a folder"),
    # -- n2r render: arguments
    ("render --transform x=1e300", "render {scene} --transform x=1e300 -o {new_png}",
     (r"--transform 'x=1e300' moves the camera too far: camera position \(.*\) is 3e\+300 scene units fr"
      r"om the captured cameras .*within 10000 reference lengths")),
    ("render --transform yaw=1e300", "render {scene} --transform yaw=1e300 -o {new_png}",
     r"yaw=1e\+300 is out of range; expected a value in \[-360, 360\]"),
    ("render --transform yaw=nan", "render {scene} --transform yaw=nan -o {new_png}",
     r"yaw=nan must be finite"),
    ("render --transform x=inf", "render {scene} --transform x=inf -o {new_png}", r"x=inf must be finite"),
    ("render --transform spin=3", "render {scene} --transform spin=3 -o {new_png}",
     r"unknown component 'spin'; expected one of \['roll', 'pitch', 'yaw'"),
    ("render --transform yaw=abc", "render {scene} --transform yaw=abc -o {new_png}",
     r"yaw='abc' is not a number"),
    ("render --transform yaw 10", "render {scene} --transform 'yaw 10' -o {new_png}",
     r"'yaw 10' is not 'name=value'"),
    ("render --transform twice", "render {scene} --transform yaw=1,yaw=2 -o {new_png}",
     r"'yaw' is given twice"),
    ("render --view 99", "render {scene} --view 99 -o {new_png}",
     r"view=99 is out of range; scene 'scene' has 4 views"),
    ("render --view -1", "render {scene} --view -1 -o {new_png}", r"view=-1 is out of range"),
    ("render --view by an unknown name", "render {scene} --view nosuch.png -o {new_png}", r"nosuch\.png"),
    ("render --size 0", "render {scene} --size 0 -o {new_png}",
     r"--size='0': longer side 0 must be in \[16, 16384\]"),
    ("render --size abc", "render {scene} --size abc -o {new_png}", r"--size='abc' is not a render size"),
    ("render --size 100x0", "render {scene} --size 100x0 -o {new_png}", r"height 0 must be in \[16, 16384\]"),
    ("render --size 100000", "render {scene} --size 100000 -o {new_png}", r"must be in \[16, 16384\] pixels"),
    ("render --units metres without a scale", "render {scene} --units metres --transform x=1 -o {new_png}",
     r"units='metres' needs a scene with a known scale; scene 'scene' has none"),
    ("render --units furlongs", "render {scene} --units furlongs -o {new_png}",
     r"invalid choice: 'furlongs'"),
    ("render --device tpu", "render {scene} --device tpu -o {new_png}",
     r"device='tpu': expected 'auto', 'cpu'"),
    ("render a missing scene", "render {tmp}/nowhere.n2r -o {new_png}",
     r"SCENE '.*nowhere\.n2r': no such file \(.*nowhere\.n2r\); expected a \.n2r scene file \(`n2r fit` writes one\)"),
    ("render an unknown scene name", "render castle -o {new_png}",
     (r"SCENE 'castle': no such file \(.*castle\); expected a \.n2r scene file \(`n2r fit` writes one\), a 3DGS "
      r"\.ply, 'demo:<name>' for a built-in demo scene, or 'module:function' returning a Scene")),
    ("render an unknown demo scene", "render demo:castle -o {new_png}",
     r"SCENE 'demo:castle': no such demo scene; expected demo: followed by one of \('wall', 'object', 'wall-field'"),
    ("render a module:function that does not import", "render nosuchmodule:scene -o {new_png}",
     r"scene 'nosuchmodule:scene': cannot import it \(No module named 'nosuchmodule'\)"),
    ("render a module:function that gives no Scene", "render os:getcwd -o {new_png}",
     r"scene 'os:getcwd' gave str, not a pytest_n2r\.Scene"),
    ("render a glob of several scenes", "render '{tmp}/odd_*.n2r' -o {new_png}",
     r"SCENE '.*odd_\*\.n2r' matched 3 scene files \(.*odd_detail\.n2r, .*\); expected one scene"),
    ("render a folder", "render {capture} -o {new_png}",
     r"capture: is a folder; expected a \.n2r scene file"),
    ("render a text file", "render {notes_txt} -o {new_png}", r"notes\.txt: not a zip archive, or truncated"),
    # -- n2r info
    ("info on a missing file", "info {tmp}/nowhere.n2r",
     r"SCENE '.*nowhere\.n2r': no such file \(.*\); expected a \.n2r scene file .* or 'module:function' returning"),
    ("info on an unknown scene name", "info castle", r"SCENE 'castle': no such file .*'demo:<name>' for a built-in"),
    ("info --shift of an exact demo scene", "info demo:wall --shift",
     r"--shift is not supported for demo:wall: it is no fitted scene file \(a GroundTruthScene\), so it has no photos"),
    ("info on a folder", "info {capture}", r"is a folder; expected a \.n2r scene file"),
    ("info on an empty file", "info {empty_n2r}", r"empty\.n2r: not a zip archive, or truncated"),
    ("info --size abc", "info {scene} --shift --size abc", r"--size='abc' is not a render size"),
    ("info on a zip without scene.json", "info {plain_zip}", r"the archive has no 'scene\.json'"),
    ("info on a report whose grid_limits rows lack their grids", "info {odd_limits}",
     r"odd_limits\.n2r: scene\.json report 'grid_limits': KeyError: 'wanted' \(not as n2r writes it\); n2r info"),
    ("info on a report whose detail holds text", "info {odd_detail}",
     r"odd_detail\.n2r: scene\.json report 'detail': ValueError: Unknown format code 'f'"),
    ("info on a report whose exposure holds text", "info {odd_exposure}",
     r"odd_exposure\.n2r: scene\.json report 'exposure': TypeError"),
    ("info on a report whose downscale is 10**400", "info {huge_downscale}",
     r"huge_downscale\.n2r: scene\.json report 'source' or 'downscale': OverflowError"),
    ("info on a zip needing version 9.1", "info {zip91_n2r}",
     r"zip91\.n2r: not a zip archive this reader can open \(zip file version 9\.1\)"),
    # -- n2r poses
    ("poses of a missing source", "poses {tmp}/nowhere", r"SOURCE .*nowhere: does not exist"),
    ("poses over the capture's transforms.json", "poses {capture} -o {capture}/transforms.json",
     r"transforms\.json: is this command's input .*transforms\.json; writing there would destroy it"),
    ("poses over another transforms.json", "poses {capture} -o {other_json}",
     r"other\.json: exists and is not a transforms\.json written by `n2r poses`.*--force"),
    ("poses -o out.txt", "poses {capture} -o {tmp}/out.txt",
     r"expected a transforms\.json written by `n2r poses`, a name ending in \.json"),
    ("poses --max-size 0", "poses {capture} --max-size 0", r"--max-size 0: expected an integer >= 1"),
    ("poses --max-size 10", "poses {capture} --max-size 10",
     r"--max-size 10: structure from motion needs images of at least 64 pixels"),
    ("poses --max-frames 0", "poses {capture} --max-frames 0", r"--max-frames 0: expected an integer >= 1"),
    ("poses --compare a missing source", "poses {capture} --compare {tmp}/nowhere",
     r"--compare .*nowhere: does not exist"),
    ("poses --frames-dir is a file", "poses {capture} --frames-dir {notes_txt}",
     r"--frames-dir .*notes\.txt: is a file; expected a folder for the video's frames"),
    ("poses --frames-dir a folder of other files", "poses {capture} --frames-dir {capture}",
     r"--frames-dir .*capture: the folder holds other files, and the video's frames would be written among them"),
    ("poses of a transforms.json nested 100 000 deep", "poses {deep_json}",
     r"deep\.json: not a readable JSON file \(nested too deeply for the JSON parser\)"),
    ("poses of a fisheye transforms.json", "poses {fisheye_json}",
     r"fisheye\.json: field 'camera_model'='FISHEYE624' is not supported; expected one of OPENCV, PINHOLE"),
    ("poses of a transforms.json whose w is 160.5 pixels", "poses {fraction_json}",
     r"fraction\.json: frames\[0\]: field 'w'=160\.5 must be a whole number of pixels"),
    ("poses of a transforms.json whose n2r.pixels is neither upright nor stored", "poses {turned_json}",
     r"turned\.json: field 'n2r\.pixels'='sideways' is not one of 'upright', 'stored'"),
    ("poses --matcher fancy", "poses {capture} --matcher fancy", r"invalid choice: 'fancy'"),
    ("poses of a folder whose photos are in DCIM/100APPLE", "poses {dcim}",
     r"images folder '.*dcim' holds no images itself; its subfolder DCIM/100APPLE holds 3 images: pass that folder$"),
    ("poses of two photos, an empty one and one cut short", "poses {two}",
     (r"images folder '.*two': only 2 of 4 images are readable; structure from motion needs at least 3\. Unreadable: "
      r"image file '.*IMG_0001\.JPG' is empty \(0 bytes: .*\); image file '.*photo_047\.jpg' cannot be decoded as an "
      r"image \(a JPEG cut short: an interrupted copy\?\)$")),
    # -- n2r import
    ("import a missing ply", "import {tmp}/nowhere.ply -o {new_n2r}", r"PLY .*nowhere\.ply: does not exist"),
    ("import with missing cameras", "import {notes_txt} --cameras {tmp}/nowhere.json -o {new_n2r}",
     r"--cameras .*nowhere\.json: does not exist"),
    ("import with a missing dataparser transform",
     "import {notes_txt} --dataparser-transforms {tmp}/nowhere.json -o {new_n2r}",
     r"--dataparser-transforms .*nowhere\.json: does not exist"),
    ("import --dataparser-transforms of a fitted scene",
     "import {scene} -o {new_n2r} --dataparser-transforms {notes_txt}",
     r"--dataparser-transforms: only for a \.ply; a fitted scene file .* brings its own views"),
    ("import over a text file", "import {notes_txt} -o {fake_n2r}", r"fake\.n2r: exists and is not a \.n2r scene file"),
    ("import to .txt", "import {notes_txt} -o {tmp}/out.txt", r"expected a \.n2r scene file, a name ending in \.n2r"),
    ("import over its own ply", "import {scene} -o {scene}", r"is this command's input"),
    ("import --heldout-every -1", "import {notes_txt} -o {new_n2r} --heldout-every=-1",
     r"--heldout-every -1: expected an int >= 0"),
    ("import --size for a ply", "import {notes_txt} -o {new_n2r} --size 0.5",
     r"--size: only for a fitted scene file \(\.n2r\); a \.ply holds its Gaussians"),
    ("import --path for a ply", "import {notes_txt} -o {new_n2r} --path 1",
     r"--path: only for a fitted scene file \(\.n2r\)"),
    ("import --size 0 of a fitted scene", "import {scene} -o {new_n2r} --size 0",
     r"--size 0\.0: expected a finite number > 0 \(voxels\)"),
    ("import --path nan of a fitted scene", "import {scene} -o {new_n2r} --path nan",
     r"--path nan: expected a finite number > 0 \(voxels\)"),
    ("import --background 2,2,2", "import {notes_txt} -o {new_n2r} --background 2,2,2",
     r"'2,2,2': expected three comma-separated values in \[0, 1\]"),
    ("import --min-coverage 2", "import {notes_txt} -o {new_n2r} --min-coverage 2",
     (r"--min-coverage 2\.0: expected a number in \[0, 1\] \(a share of the training views' pixels; 0 skips "
      r"the check\)")),
    ("import --min-coverage nan", "import {notes_txt} -o {new_n2r} --min-coverage nan",
     r"--min-coverage nan: expected a number in \[0, 1\]"),
    # -- n2r demo
    ("demo export of an unknown scene", "demo export castle -o {tmp}/export",
     r"NAME 'castle': no such demo scene; expected one of"),
    ("demo export into a file", "demo export object -o {notes_txt}",
     r"notes\.txt: is a file; expected a folder"),
    ("demo export among other files", "demo export object -o {capture}",
     r"capture: the folder holds other files, and the export .* would be written among them.*pass --force"),
    ("demo export --size 0x0", "demo export object -o {tmp}/export --size 0x0",
     r"width and height must be 8\.\.4096 pixels"),
    ("demo export --size huge", "demo export object -o {tmp}/export --size 100000", r"8\.\.4096 pixels"),
    ("demo export --size abc", "demo export object -o {tmp}/export --size abc",
     r"size 'abc': expected WIDTHxHEIGHT"),
    ("demo build of an unknown scene", "demo build castle -o {tmp}/built",
     r"no fitted recipe for \['castle'\]"),
    ("demo build into a file", "demo build object -o {notes_txt}",
     r"notes\.txt: is a file; expected a folder"),
    # -- n2r study
    ("study --examples 0", "study {scene} --sut orb -o {tmp}/study --examples 0",
     r"--examples 0: expected an integer >= 1"),
    ("study --views 0", "study {scene} --sut orb -o {tmp}/study --views 0",
     r"--views 0: expected an integer >= 1"),
    ("study --fps-frames 0", "study {scene} --sut orb -o {tmp}/study --fps-frames 0", r"--fps-frames 0"),
    ("study --size 5", "study {scene} --sut orb -o {tmp}/study --size 5",
     r"--size 5: expected the longer side of the test renders in 16\.\.4096"),
    ("study --eps -1", "study {scene} --sut orb -o {tmp}/study --eps=-1",
     r"--eps '-1': expected one or more numbers >= 0"),
    ("study --eps abc", "study {scene} --sut orb -o {tmp}/study --eps abc", r"--eps 'abc': expected numbers"),
    ("study --fps-size 0x10", "study {scene} --sut orb -o {tmp}/study --fps-size 0x10",
     r"width and height must be 1\.\.8192 pixels"),
    ("study into a file", "study {scene} --sut orb -o {notes_txt}",
     r"notes\.txt: is a file; expected a folder"),
    ("study among other files", "study {scene} --sut orb -o {capture}", r"the folder holds other files"),
    ("study without --sut", "study {scene} -o {tmp}/study", r"the following arguments are required: --sut"),
    ("study of a missing scene", "study {tmp}/nowhere.n2r --sut orb -o {tmp}/study",
     r"SCENE .*nowhere\.n2r.*: no such file"),
    ("study of an unknown demo scene", "study demo:castle --sut orb -o {tmp}/study",
     r"SCENE 'demo:castle': no such demo scene"),
    ("study --seed abc", "study {scene} --sut orb -o {tmp}/study --seed abc",
     r"argument --seed: invalid int value"),
    ("study --device tpu", "study {scene} --sut orb -o {tmp}/study --device tpu",
     r"device='tpu': expected 'auto', 'cpu' or 'cuda\[:N\]'"),
    ("study --sut-kind orb=banana", "study {scene} --sut orb -o {tmp}/study --sut-kind orb=banana",
     r"--sut-kind 'orb=banana': expected detector or classifier"),
    ("study --sut-kind of no --sut", "study {scene} --sut orb -o {tmp}/study --sut-kind sift=detector",
     r"--sut-kind sift=detector: 'sift' is not one of the --sut given"),
    ("study --points 0", "study {scene} --sut orb -o {tmp}/study --points 0",
     r"--points 0: expected a positive integer, the number of highest-response points"),
]


def _snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> dict[str, str]:
    """A scene file, a capture folder and decoys (a text file named .png, another transforms.json ...)."""
    tmp = tmp_path_factory.mktemp("workspace")
    scene = save_scene(tmp / "scene.n2r", random_field(), FieldConfig(), tiny_views(), {}, reference_length=3.0)
    capture = tmp / "capture"
    (capture / "images").mkdir(parents=True)
    (capture / "transforms.json").write_text('{"frames": []}\n')
    (tmp / "notes.txt").write_text("my notes\n")
    for name in ("fake.n2r", "fake.png", "note.depth.png", "note.opacity.png"):
        (tmp / name).write_text("not what it seems\n")
    (tmp / "other.json").write_text('{"camera_model": "OPENCV", "frames": []}\n')
    (tmp / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (tmp / "fisheye.json").write_text(json.dumps({"camera_model": "FISHEYE624", "frames": [
        {"file_path": "x.png", "transform_matrix": np.eye(4).tolist()}]}))
    corner_capture = make_capture(tmp / "corner", n=4)
    corner = write_transforms(corner_capture)
    write_transforms(corner_capture, tmp / "corner" / "fraction.json", w=160.5)
    (tmp / "turned").mkdir()
    exif = Image.Exif()
    exif[0x0112] = 6  # a phone's portrait photo: landscape pixels, shown turned a quarter
    Image.new("RGB", (64, 48)).save(tmp / "turned" / "p.jpg", exif=exif.tobytes())
    (tmp / "turned" / "turned.json").write_text(json.dumps({"fl_x": 50, "n2r": {"pixels": "sideways"}, "frames": [
        {"file_path": "p.jpg", "transform_matrix": np.eye(4).tolist()}]}))
    (tmp / "dcim" / "DCIM" / "100APPLE").mkdir(parents=True)  # a phone's folders copied as they are
    for k in range(3):
        shutil.copy(tmp / "corner" / "images" / f"view_{k:03d}.png", tmp / "dcim" / "DCIM" / "100APPLE" / f"{k}.png")
    two = tmp / "two"
    two.mkdir()
    for k in range(2):
        shutil.copy(tmp / "corner" / "images" / f"view_{k:03d}.png", two / f"photo_{k:03d}.png")
    (two / "IMG_0001.JPG").write_bytes(b"")  # a cloud photo not downloaded
    _, jpeg = cv2.imencode(".jpg", np.random.default_rng(0).integers(0, 256, (48, 64, 3), np.uint8))
    (two / "photo_047.jpg").write_bytes(jpeg.tobytes()[:len(jpeg) // 2])  # an interrupted copy
    (tmp / "empty.n2r").write_bytes(b"")
    with zipfile.ZipFile(tmp / "plain.n2r", "w") as archive:
        archive.writestr("readme.txt", "no scene here")
    for name, report in (("odd_limits", {"grid_limits": [{"step": 21}]}),
                         ("odd_detail", {"detail": {"pixels_per_voxel": "fine", "matching_resolution": 1}}),
                         ("odd_exposure", {"exposure": "varied"})):
        save_scene(tmp / f"{name}.n2r", random_field(), FieldConfig(), tiny_views(), report, reference_length=3.0)
    save_scene(tmp / "huge_downscale.n2r", random_field(), FieldConfig(), tiny_views(),  # not odd_*: a glob case
               {"source": "x", "downscale": 10**400}, reference_length=3.0)
    _needing_zip_version(shutil.copy(scene, tmp / "zip91.n2r"), 91)
    return {"tmp": str(tmp), "scene": str(scene), "capture": str(capture), "notes_txt": str(tmp / "notes.txt"),
            "fake_n2r": str(tmp / "fake.n2r"), "fake_png": str(tmp / "fake.png"), "new_n2r": str(tmp / "new.n2r"),
            "new_png": str(tmp / "new.png"), "other_json": str(tmp / "other.json"),
            "empty_n2r": str(tmp / "empty.n2r"), "plain_zip": str(tmp / "plain.n2r"),
            "odd_limits": str(tmp / "odd_limits.n2r"), "odd_detail": str(tmp / "odd_detail.n2r"),
            "odd_exposure": str(tmp / "odd_exposure.n2r"), "huge_downscale": str(tmp / "huge_downscale.n2r"),
            "zip91_n2r": str(tmp / "zip91.n2r"), "deep_json": str(tmp / "deep.json"),
            "fisheye_json": str(tmp / "fisheye.json"), "corner": str(corner), "dcim": str(tmp / "dcim"),
            "two": str(two), "fraction_json": str(tmp / "corner" / "fraction.json"),
            "turned_json": str(tmp / "turned" / "turned.json")}


def _needing_zip_version(path: str | Path, version: int) -> Path:
    """Patch the zip ``path`` in place so that its central directory says every member needs zip ``version``
    (91: "9.1") to extract: Python's zipfile raises NotImplementedError on opening it."""
    data = bytearray(Path(path).read_bytes())
    at = data.find(b"PK\x01\x02")
    while at >= 0:
        data[at + 6:at + 8] = version.to_bytes(2, "little")
        at = data.find(b"PK\x01\x02", at + 4)
    Path(path).write_bytes(bytes(data))
    return Path(path)


def _argv(template: str, workspace: dict[str, str]) -> list[str]:
    import shlex

    return [part.format(**workspace) for part in shlex.split(template)]


@pytest.mark.parametrize(("command", "expected"), [c[1:] for c in COMMAND_CASES], ids=[c[0] for c in COMMAND_CASES])
def test_a_bad_command_line_is_refused_with_a_message_and_changes_nothing(command, expected, workspace, capsys):
    before = _snapshot(Path(workspace["tmp"]))
    try:
        code = main(_argv(command, workspace))  # an exception escaping main would be a traceback
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    err = capsys.readouterr().err
    assert code not in (0, None), f"exit code {code} for {command!r}; stderr:\n{err}"
    assert "Traceback" not in err, err
    one_line = " ".join(err.split())
    assert re.search(expected, one_line), f"expected /{expected}/ in:\n{err}"
    assert _snapshot(Path(workspace["tmp"])) == before, f"{command!r} changed a file"


def test_the_catalogue_covers_every_command_and_option():
    """Every option of every command that takes a value has at least one bad-input case."""
    from pytest_n2r.cli.main import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    missing = []
    for name, command in sub.choices.items():
        cases = [c[1].split() for c in COMMAND_CASES if c[1].split()[0] == name]
        parsers = {name: command}
        for action in command._actions:
            if action.dest == "demo_command":
                parsers = {f"{name} {action_name}": p for action_name, p in action.choices.items()}
        for label, p in parsers.items():
            words = {w.split("=")[0] for case in cases if " ".join(case).startswith(label) for w in case}
            if not words and any(a.option_strings and a.nargs != 0 and a.dest != "help" for a in p._actions):
                missing.append(label)
            for action in p._actions:
                takes_value = action.nargs != 0 and action.option_strings and action.dest != "help"
                if takes_value and not words & set(action.option_strings):
                    missing.append(f"{label} {action.option_strings[-1]}")
    assert not missing, f"options with no bad-input case: {missing}"


def test_force_replaces_a_file_that_is_not_its_kind_and_the_result_is_its_kind(workspace, tmp_path, capsys):
    target = tmp_path / "view.png"
    target.write_text("an old note\n")
    assert main(["render", workspace["scene"], "--size", "20", "-o", str(target), "--force"]) == 0, \
        capsys.readouterr().err
    assert target.read_bytes().startswith(b"\x89PNG")


def test_render_depth_beside_a_depth_named_image_keeps_both(workspace, tmp_path, capsys):
    out = tmp_path / "view.depth.png"
    assert main(["render", workspace["scene"], "--size", "20", "--depth", "-o", str(out)]) == 0, \
        capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["view.depth.depth.npy", "view.depth.depth.png",
                                                          "view.depth.png"]


# -- scene files: what a reader refuses, and with how much memory ----------------------------------------------


def _set(path: str, value):
    """An edit of ``scene.json`` setting the dotted ``path`` (``frames.0.c2w``) to ``value``."""
    def edit(data):
        *parents, last = path.split(".")
        for key in parents:
            data = data[int(key)] if key.isdigit() else data[key]
        data[int(last) if last.isdigit() else last] = value
    return edit


def _huge_jpeg(good: Path) -> bytes:
    """The scene's first photo with its start-of-frame marker claiming 60000 x 60000 pixels."""
    with zipfile.ZipFile(good) as archive:
        jpeg = bytearray(archive.read(next(n for n in archive.namelist() if n.startswith("images/"))))
    sof = jpeg.index(b"\xff\xc0")
    jpeg[sof + 5:sof + 9] = (60000).to_bytes(2, "big") * 2
    return bytes(jpeg)


def _field_values(value: float) -> bytes:
    import safetensors.torch

    tensors = random_field().tensors()
    tensors["vertex_values"] = torch.full_like(tensors["vertex_values"], value)
    return safetensors.torch.save(tensors)


def _tensor_header(header: dict) -> bytes:
    """A safetensors file that is only a header (no tensor data)."""
    text = json.dumps(header).encode()
    return len(text).to_bytes(8, "little") + text


#: (id, how the good scene file is broken, regex of the SceneFileError); an int in ``replace`` is that many
#: zero bytes, streamed into the archive (a member that inflates to that much)
SCENE_FILE_CASES = [
    ("metres_per_unit -1", {"edit": _set("metres_per_unit", -1)},
     r"metres_per_unit=-1; expected a finite number > 0 or null"),
    ("reference_length 0", {"edit": _set("reference_length", 0)}, r"reference_length=0; expected a finite number"),
    ("reference_length a string", {"edit": _set("reference_length", "3")}, r"reference_length='3'"),
    ("version from the future", {"edit": _set("version", 99)}, r"format version 99.*upgrade pytest-n2r"),
    ("another format", {"edit": _set("format", "zip")}, r"format='zip'.*not a pytest-n2r scene file"),
    ("no frames", {"edit": _set("frames", [])}, r"'frames' must be a non-empty list"),
    ("a pose with NaN", {"edit": _set("frames.0.c2w.0.3", float("nan"))},
     r"scene\.json is not valid JSON \(NaN is not a number in strict JSON"),
    ("a pose at 1e300", {"edit": _set("frames.0.c2w.0.3", 1e300)},
     r"frames\[0\]\.c2w puts the camera 1e\+300 scene units from the bounds' centre; expected within 10000"),
    ("a pose that is no rotation", {"edit": _set("frames.0.c2w.0.0", 5.0)},
     r"frames\[0\]\.c2w rotation block is not a rotation"),
    ("an unknown split", {"edit": _set("frames.0.split", "test")}, r"frames\[0\]\.split='test'"),
    ("a camera index out of range", {"edit": _set("frames.0.camera", 7)},
     r"frames\[0\]\.camera=7; expected an index into the 1 cameras"),
    ("an image member outside images/", {"edit": _set("frames.0.image", "../../etc/passwd")},
     r"frames\[0\]\.image='\.\./\.\./etc/passwd'"),
    ("a camera of negative width", {"edit": _set("cameras.0.width", -20)},
     r"cameras\[0\]\.width=-20; expected a whole number of pixels in 1\.\.16384"),
    ("a camera width as a string", {"edit": _set("cameras.0.width", "20")}, r"cameras\[0\]\.width='20'"),
    ("a camera a trillion pixels wide", {"edit": _set("cameras.0.width", 10**12)},
     r"cameras\[0\]\.width=1000000000000; expected a whole number of pixels in 1\.\.16384"),
    ("a camera of negative focal length", {"edit": _set("cameras.0.fx", -1)}, r"cameras\[0\] is not a valid camera"),
    ("cameras a number", {"edit": _set("cameras", 5)}, r"'cameras' must be a non-empty list of camera objects"),
    ("a camera that is a list", {"edit": _set("cameras.0", [1, 2])}, r"cameras\[0\]=\[1, 2\]; expected a camera"),
    ("bounds min above max", {"edit": _set("bounds", [[1, 1, 1], [-1, -1, -1]])},
     r"expected \[\[min x, y, z\], \[max x, y, z\]\] \(scene units, each min at most its max\)"),
    ("normalization shell -5", {"edit": _set("normalization.shell", -5)},
     r"field metadata is incomplete or invalid \(shell=-5\.0: expected a thickness in \(0, 4\]"),
    ("density_shift a string", {"edit": _set("field.density_shift", "x")},
     r"field\.density_shift='x'; expected a finite number"),
    ("background a string", {"edit": _set("field.background", "x")}, r"field\.background='x'; expected three values"),
    ("bounds not a box", {"edit": _set("bounds", [1, 2])}, r"bounds=\[1, 2\]; expected \[\[min x, y, z\]"),
    ("density_shift 1e30", {"edit": _set("field.density_shift", 1e30)},
     r"density_shift=1e\+30; expected a finite number within ±100"),
    ("normalization radius 1e-300", {"edit": _set("normalization.radius", 1e-300)},
     r"normalization\.radius=1e-300; expected a number within a factor 10000 of the reference length"),
    ("normalization centre 1e300", {"edit": _set("normalization.center", [1e300, 0, 0])},
     r"normalization\.center=\[1e\+300, 0, 0\]; expected three numbers within 10000 reference lengths"),
    ("grid resolution 5000", {"edit": _set("field.resolution", 5000)},
     r"field\.resolution=5000; expected an integer in 4\.\.2048"),
    ("SH degree 3", {"edit": _set("field.sh_degree", 3)}, r"field\.sh_degree=3; expected 0, 1 or 2"),
    ("reference_length 10**400", {"edit": _set("reference_length", 10**400)},
     r"scene\.json reference_length=10{400}; expected a finite number > 0"),
    ("metres_per_unit 10**400", {"edit": _set("metres_per_unit", 10**400)},
     r"scene\.json metres_per_unit=10{400}; expected a finite number > 0 or null"),
    ("a pose holding 10**400", {"edit": _set("frames.0.c2w.0.3", 10**400)},
     r"scene\.json frames\[0\]\.c2w holds a number beyond float's range"),
    ("normalization centre 10**400", {"edit": _set("normalization.center", [10**400, 0, 0])},
     r"normalization\.center=\[10{400}, 0, 0\]; expected three numbers"),
    ("bounds holding 10**400", {"edit": _set("bounds", [[-1, -1, -1], [10**400, 1, 1]])},
     r"scene\.json bounds=\[\[-1, -1, -1\], \[10{400}, 1, 1\]\]; expected \[\[min x, y, z\]"),
    ("background 10**400", {"edit": _set("field.background", [10**400, 0, 0])},
     r"field\.background=\[10{400}, 0, 0\]; expected three values in \[0, 1\]"),
    ("a config with seed 'x'", {"edit": _set("config.seed", "x")},
     r"'config' is not a valid FieldConfig \(FieldConfig\.seed='x'"),
    ("scene.json nested 100 000 deep", {"replace": {SCENE_JSON: b"[" * 100_000 + b"]" * 100_000}},
     r"scene\.json is not valid JSON"),
    ("scene.json inflating past 64 MiB", {"replace": {SCENE_JSON: 65 * 2**20}},
     r"'scene\.json' inflates to 68,157,440 bytes, more than the 67,108,864 bytes the cap on scene\.json allows"),
    ("field member inflating to 1 GB", {"replace": {FIELD_FILE: 2**30}},
     r"field\.safetensors is not a valid safetensors file \(its header claims 0 bytes"),
    ("field header claiming 1 GB of tensors", {"replace": {FIELD_FILE: _tensor_header(
        {"occupancy": {"dtype": "U8", "shape": [2**30], "data_offsets": [0, 2**30]}})}},
     r"its tensors claim 1,073,741,824 bytes, more than the declared 12³ grid of SH degree 1 can hold"),
    ("field values beyond float16", {"replace": {FIELD_FILE: "inf values"}},
     r"tensor 'vertex_values' holds NaN or Inf"),
    ("a photo claiming 60000x60000 pixels", {"replace": {"images/frame_000.jpg": "huge jpeg"}},
     r"images/frame_000\.jpg is 60000x60000 pixels; frame 'frame_000\.png' has a 20x16 camera"),
    # an empty field declaring a 1024³ grid (a 1 MB file) took torch's allocator down with a bare RuntimeError:
    # the free memory is read as 256 MiB here rather than gigabytes allocated
    ("a 1024³ grid with 256 MiB free", {"edit": _set("field.resolution", 1024), "free": 2**28},
     (r"field\.safetensors: the 1024³ grid of scene\.json field\.resolution would take about 7\.\d+ GiB to "
      r"decode, more than the 0\.25 GiB of memory free")),
    ("4096² photos with 64 MiB free", {"edit": _set("cameras.0", {**tiny_views()[0].camera.to_dict(),
                                                                 "width": 4096, "height": 4096}), "free": 2**26},
     r"scene\.json: the 4 photos its frames name \(width x height of their cameras\) would take about 0\.19 GiB"),
    ("a zip needing version 9.1", {"zip_version": 91},
     r"not a zip archive this reader can open \(zip file version 9\.1\)"),
]


@pytest.fixture(scope="module")
def good_scene(tmp_path_factory) -> Path:
    return save_scene(tmp_path_factory.mktemp("good") / "good.n2r", random_field(), FieldConfig(), tiny_views(), {},
                      reference_length=3.0)


@pytest.mark.parametrize(("how", "expected"), [c[1:] for c in SCENE_FILE_CASES], ids=[c[0] for c in SCENE_FILE_CASES])
def test_a_bad_scene_file_is_a_scene_file_error_in_bounded_memory(how, expected, good_scene, tmp_path, monkeypatch):
    built = {"huge jpeg": lambda: _huge_jpeg(good_scene), "inf values": lambda: _field_values(float("inf"))}
    how = {**how, "replace": {k: built[v]() if isinstance(v, str) else v for k, v in how.get("replace", {}).items()}}
    bad = rewrite(good_scene, tmp_path / "bad.n2r", edit_json=how.get("edit"), replace=how["replace"])
    if "zip_version" in how:
        _needing_zip_version(bad, how["zip_version"])
    if "free" in how:
        monkeypatch.setattr("pytest_n2r.scene.memory_guard.cpu_free_bytes", lambda: how["free"])
    _refused_in_bounded_memory(read_scene_file, bad, expected)


#: the cases of ``scene.json`` alone (with the memory free, where a case sets it), which check_scene_file refuses too
JSON_CASES = [c for c in SCENE_FILE_CASES if "edit" in c[1] and set(c[1]) <= {"edit", "free"}
              and "photos" not in c[2]]


@pytest.mark.parametrize("edit, expected", [c[1:] for c in JSON_CASES], ids=[c[0] for c in JSON_CASES])
def test_check_scene_file_refuses_what_the_reader_refuses_in_scene_json(edit, expected, good_scene, tmp_path,
                                                                       monkeypatch):
    """The plugin checks every scene file at start-up with :func:`check_scene_file` (no inflating): a fault
    of ``scene.json`` must stop it there, not at the first render."""
    if "free" in edit:
        monkeypatch.setattr("pytest_n2r.scene.memory_guard.cpu_free_bytes", lambda: edit["free"])
    bad = rewrite(good_scene, tmp_path / "bad.n2r", edit_json=edit["edit"])
    with pytest.raises(SceneFileError) as info:
        check_scene_file(bad)
    assert re.search(expected, str(info.value)), f"expected /{expected}/ in:\n{info.value}"


def _refused_in_bounded_memory(read, bad: Path, expected: str) -> None:
    """``read(bad)`` raises a :class:`SceneFileError` matching ``expected`` and naming the file, within
    40 MiB of Python memory (tracemalloc: NumPy's buffers included)."""
    tracemalloc.start()
    try:
        with pytest.raises(SceneFileError) as info:
            read(bad)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert re.search(expected, str(info.value)), f"expected /{expected}/ in:\n{info.value}"
    assert str(bad) in str(info.value), "the message does not name the file"
    assert peak < 40 * 2**20, f"reading the bad file took {peak / 2**20:.0f} MiB of Python memory"


def test_an_unreadable_scene_is_never_written_over_a_good_one(good_scene, tmp_path):
    target = shutil.copy(good_scene, tmp_path / "scene.n2r")
    before = Path(target).read_bytes()
    for bad in ({"metres_per_unit": -1.0}, {"metres_per_unit": float("nan")}, {"reference_length": 0.0}):
        with pytest.raises(ValueError, match=r"save_scene: (metres_per_unit|reference_length)="):
            save_scene(target, random_field(), FieldConfig(), tiny_views(), {}, **{"reference_length": 3.0, **bad})
    field = random_field()
    field.values[0, 0] = 1e6  # beyond float16
    with pytest.raises(ValueError, match=r"beyond float16's ±65504.*nothing was written"):
        save_scene(target, field, FieldConfig(), tiny_views(), {}, reference_length=3.0)
    assert Path(target).read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.n2r"], "a temporary file was left behind"


def test_a_render_far_beyond_the_scene_is_an_error_not_a_black_picture(good_scene):
    from pytest_n2r.scene import load_scene

    scene = load_scene(good_scene, device="cpu", images=False)
    view = scene.views[0]
    far = view.c2w.copy()
    far[:3, 3] += np.array([0.0, 0.0, 1e12])
    with pytest.raises(ValueError, match=r"is 1e\+12 scene units from the captured cameras of scene 'good'"):
        scene.render(far, view.camera)


def test_the_reliability_page_counts_this_catalogue():
    from ..plugin.test_bad_options import OPTION_CASES

    page = (Path(__file__).resolve().parents[2] / "docs" / "reliability.md").read_text(encoding="utf-8")
    for label, cases in (("commands, total", COMMAND_CASES), ("scene files, total", SCENE_FILE_CASES)):
        assert f"| **{label}** | **{len(cases)}** |" in page, f"docs/reliability.md: {label} is not {len(cases)}"
    assert re.search(rf"\| plugin options: .* \| {len(OPTION_CASES)} \|", page), "the plugin options' count"


def test_a_splat_scene_file_whose_tensors_inflate_to_a_gigabyte_is_refused_before_inflating(good_scene, tmp_path):
    from pytest_n2r.scene import load_scene

    def as_splats(data):
        data["representation"] = "splats"
        data["splats"] = {"count": 3, "sh_degree": 0, "background": [0, 0, 0]}

    bad = rewrite(good_scene, tmp_path / "splats.n2r", edit_json=as_splats, replace={"splats.safetensors": 2**30})
    _refused_in_bounded_memory(load_scene, bad, r"'splats\.safetensors' inflates to 1,073,741,824 bytes, more than "
                                                r"the 1,048,744 bytes 3 float32 Gaussians of SH degree 0 allows")


def test_a_splat_scene_file_declaring_more_gaussians_than_memory_holds_is_refused(good_scene, tmp_path, monkeypatch):
    """``splats.count`` sizes the read: 10⁹ Gaussians of SH degree 3 (708 GB of float32) are refused from the
    count alone, before the member is read (the free memory is read as 1 GiB here)."""
    from pytest_n2r.scene import load_scene

    def as_splats(data):
        data["representation"] = "splats"
        data["splats"] = {"count": 10**9, "sh_degree": 3, "background": [0, 0, 0]}

    monkeypatch.setattr("pytest_n2r.scene.memory_guard.cpu_free_bytes", lambda: 2**30)
    bad = rewrite(good_scene, tmp_path / "splats.n2r", edit_json=as_splats, replace={"splats.safetensors": b"x"})
    _refused_in_bounded_memory(load_scene, bad, r"scene\.json: splats\.count=1,000,000,000 Gaussians of SH degree 3 "
                                                r"would take about 659\.\d+ GiB to decode, more than the 1\.00 GiB")


@pytest.mark.parametrize("background", ["101", [True, False, True]], ids=repr)
def test_a_background_that_is_no_three_numbers_is_refused_in_a_scene_file(background, good_scene, tmp_path):
    """``field.background`` or ``splats.background`` of ``"101"`` was read character by character (as magenta),
    ``[true, false, true]`` as 1, 0, 1."""
    from pytest_n2r.scene import load_scene

    bad = rewrite(good_scene, tmp_path / "bad.n2r", edit_json=_set("field.background", background))
    expected = rf"field\.background={re.escape(repr(background))}; expected three values in \[0, 1\]"
    _refused_in_bounded_memory(read_scene_file, bad, expected)
    with pytest.raises(SceneFileError, match=expected):
        check_scene_file(bad)

    def as_splats(data):
        data["representation"] = "splats"
        data["splats"] = {"count": 3, "sh_degree": 0, "background": background}

    bad = rewrite(good_scene, tmp_path / "splats.n2r", edit_json=as_splats, replace={"splats.safetensors": b"x"})
    _refused_in_bounded_memory(load_scene, bad, rf"splats\.background=.*'background': "
                                                rf"{re.escape(repr(background))}.*; expected three values in \[0, 1\]")
