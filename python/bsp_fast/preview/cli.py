"""Command line of bsp-preview (console script ``bsp-preview``)."""
from __future__ import annotations

import argparse
import sys

from ..command_line import ArgumentParser, BadInput, run_command


def _ints(text: str) -> list:
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}")


def _common(p, fps_default: float) -> None:
    p.add_argument("--out", required=True, metavar="OUT.png|OUT.mp4",
                   help="output picture (.png) or video (.mp4, H.264); written under a "
                        "temporary name and renamed")
    p.add_argument("--fps", type=float, default=fps_default,
                   help=f"frame rate of an .mp4 output (default: {fps_default:g})")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-preview",
        description="Draw CARLA-BSP data to look at it: a recording's frames with skeleton "
                    "and segmentation, a contact sheet of converted clips, a clip's 3D "
                    "skeleton, or predictions against the ground truth. Bones are coloured "
                    "by side: left blue, right orange, centre green.",
        epilog="Exit codes (docs/architecture.md): 0 written, 1 a missing or unreadable "
               "input (media, HDF5) or the 'preview' extra (OpenCV, matplotlib) not "
               "installed, 2 bad arguments (unknown recording or clip, wrong extension, OUT "
               "is one of the inputs, --force or not), 3 OUT exists (--force replaces it). "
               "Details: docs/preview.md.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    _frames_parser(sub)
    _clips_parser(sub)
    _pose3d_parser(sub)
    _predictions_parser(sub)
    return p


def _frames_parser(sub) -> None:
    f = sub.add_parser("frames", help="video frames of one recording with annotations",
                       description="RGB frames of one recording with the 2D skeleton "
                                   "(pose.camera), the joint bbox, the crossing label and the "
                                   "frame number, and the segmentation in Cityscapes colours.")
    f.add_argument("dataset", metavar="DATASET", help="dataset directory (or its data.csv)")
    f.add_argument("--recording", required=True, metavar="ID",
                   help="an id of data.csv, a unique prefix of one, or its 0-based index in "
                        "data.csv order")
    f.add_argument("--frames", metavar="START:STOP:STEP",
                   help="video frames to draw: a slice, 'A,B,C' or one number (default: 4 "
                        "frames over the annotated ones for PNG; every frame from the first "
                        "to the last annotated one for MP4)")
    f.add_argument("--layout", choices=("side", "blend", "rgb"), default="side",
                   help="segmentation beside the RGB frame, blended over it, or left out "
                        "(default: %(default)s)")
    f.add_argument("--alpha", type=float, default=0.5,
                   help="opacity of the segmentation with --layout blend (default: 0.5)")
    f.add_argument("--scale", type=float, default=1.0,
                   help="resize the frames by this factor before drawing (default: 1)")
    f.add_argument("--cols", type=int, default=1, help="frames per row of a PNG (default: 1)")
    f.add_argument("--camera", type=int, help="camera.idx (default: the recording's first)")
    f.add_argument("--pedestrian", type=int,
                   help="pedestrian.idx (default: the recording's first)")
    _common(f, 30.0)


def _clips_parser(sub) -> None:
    c = sub.add_parser("clips", help="contact sheet of the clips of a bsp-convert file",
                       description="A grid of clips: the pedestrian crop with its skeleton "
                                   "when the file holds media (joints hidden in the mask are "
                                   "rings), the skeleton alone otherwise; captions give label "
                                   "and ids.")
    c.add_argument("clips_h5", metavar="CLIPS.h5", help="output of bsp-convert")
    c.add_argument("--split", choices=("train", "val", "test"), default="train",
                   help="split to draw from (default: %(default)s)")
    c.add_argument("--n", type=int, default=16, help="clips to draw (default: 16)")
    c.add_argument("--clips", type=_ints, metavar="I,J,...",
                   help="clip indices of the split instead of the first --n")
    c.add_argument("--seed", type=int, help="draw --n clips at random with this seed")
    c.add_argument("--frame", default="middle",
                   help="clip frame shown: first, middle, last or a number (default: middle)")
    c.add_argument("--size", type=int, default=128, help="panel side in pixels (default: 128)")
    c.add_argument("--cols", type=int, help="panels per row (default: about square)")
    _common(c, 10.0)


def _pose3d_parser(sub) -> None:
    d = sub.add_parser("pose3d", help="a clip's 3D skeleton from two viewpoints",
                       description="The 3D joint locations of one clip (matplotlib), from the "
                                   "front and from the side, axes fixed over the clip.")
    d.add_argument("clips_h5", metavar="CLIPS.h5", help="output of bsp-convert")
    d.add_argument("--clip", type=int, required=True, metavar="N", help="clip index in the split")
    d.add_argument("--split", choices=("train", "val", "test"), default="train",
                   help="split (default: %(default)s)")
    d.add_argument("--space", choices=("component", "world"), default="component",
                   help="component: targets/absolute_pose_loc (the actor's frame); world: "
                        "targets/world_pose_loc (default: %(default)s)")
    d.add_argument("--frame", default="middle",
                   help="clip frame of a PNG: first, middle, last or a number (default: "
                        "middle); an MP4 shows every frame")
    d.add_argument("--size", default="800x400", help="picture size WxH (default: 800x400)")
    _common(d, 30.0)


def _predictions_parser(sub) -> None:
    r = sub.add_parser("predictions", help="ground truth vs predictions of bsp-predict",
                       description="Ground truth (green) against the prediction (magenta): "
                                   "2D tasks as a sheet of clips (pose estimation on its crops, "
                                   "the autoencoder over its noisy input in grey), lifting in "
                                   "3D from the front and from the side.")
    r.add_argument("preds_h5", metavar="PREDS.h5", help="output of bsp-predict")
    r.add_argument("--n", type=int, default=16, help="2D: clips to draw (default: 16)")
    r.add_argument("--clips", type=_ints, metavar="I,J,...", help="2D: clip indices instead")
    r.add_argument("--clip", type=int, default=0, help="lifting: the clip drawn (default: 0)")
    r.add_argument("--frame", default="middle",
                   help="frame of a PNG: first, middle, last or a number (default: middle)")
    r.add_argument("--size", help="2D: panel side in pixels (default: 160); lifting: WxH "
                                  "(default: 800x400)")
    r.add_argument("--cols", type=int, help="2D: panels per row (default: about square)")
    r.add_argument("--clips-h5", metavar="CLIPS.h5",
                   help="pose estimation: the converted file holding the crops (default: the "
                        "one bsp-predict read, its 'source' attribute)")
    _common(r, 10.0)


def _run(args) -> dict:
    from . import preview_clips, preview_frames, preview_pose3d, preview_predictions

    if args.command == "frames":
        return preview_frames(args.dataset, args.recording, args.out, frames=args.frames,
                              layout=args.layout, alpha=args.alpha, scale=args.scale,
                              cols=args.cols, camera=args.camera, pedestrian=args.pedestrian,
                              fps=args.fps, force=args.force)
    if args.command == "clips":
        return preview_clips(args.clips_h5, args.out, split=args.split, n=args.n,
                             clips=args.clips, frame=args.frame, size=args.size,
                             cols=args.cols, seed=args.seed, fps=args.fps, force=args.force)
    if args.command == "pose3d":
        return preview_pose3d(args.clips_h5, args.clip, args.out, split=args.split,
                              space=args.space, frame=args.frame, size=args.size,
                              fps=args.fps, force=args.force)
    size = args.size
    if size is not None and "x" not in size:
        size = int(size)
    return preview_predictions(args.preds_h5, args.out, clips=args.clips, n=args.n,
                               clip=args.clip, frame=args.frame, size=size, cols=args.cols,
                               fps=args.fps, force=args.force, clips_h5=args.clips_h5)


def _check_outputs(args) -> None:
    """The output rule (bsp_fast.atomic.check_outputs), before any file is read: OUT is
    none of the command's inputs (for ``frames``: data.csv, config.yaml or a media file
    of the dataset)."""
    from pathlib import Path

    from ..atomic import DATASET_FILES, check_outputs

    read_dirs = []
    if args.command == "frames":
        p = Path(args.dataset)
        root, csv = (p, p / "data.csv") if p.is_dir() else (p.parent, p)
        inputs = [("the dataset", root), ("the dataset's input", csv)]
        read_dirs.append(("the dataset", root, DATASET_FILES))
    elif args.command == "predictions":
        inputs = [("the input", args.preds_h5), ("the --clips-h5 file", args.clips_h5)]
    else:
        inputs = [("the input", args.clips_h5)]
    check_outputs(inputs=inputs, outputs=[("--out", args.out)], read_dirs=read_dirs)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run_command("bsp-preview", _main, args)


def _check_inputs(args) -> None:
    """Each input exists (a missing one is exit 1, named, before any file is opened)."""
    from pathlib import Path

    if args.command == "frames":
        from ..conversion.inputs import dataset_csv

        dataset_csv(args.dataset)
    for path in (getattr(args, "preds_h5", None), getattr(args, "clips_h5", None)):
        if path is not None and not Path(path).is_file():
            raise FileNotFoundError(f"{path}: no such file")


def _main(args) -> None:
    _check_outputs(args)  # the output rule first, as every command: an input is never OUT
    _check_inputs(args)
    try:
        res = _run(args)
    except KeyError as exc:  # h5py: an input file without a group or dataset it needs
        name = getattr(args, "preds_h5", None) or getattr(args, "clips_h5", None) \
            or args.dataset
        raise BadInput(f"{name}: {exc.args[0] if exc.args else exc}") from exc
    w, h = res["size"]
    print(f"wrote {res['path']} ({w}x{h}, {res['frames']} frame(s))")


if __name__ == "__main__":
    sys.exit(main())
