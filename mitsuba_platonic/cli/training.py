"""``platonic quickstart``, ``train`` and ``evaluate``: the pipeline, its training and its scores.

- ``quickstart``: :func:`mitsuba_platonic.quickstart.procedural.quickstart` (a procedural collection) or
  :func:`mitsuba_platonic.quickstart.photos.photo_quickstart` (``--photos DIR``) or
  :func:`mitsuba_platonic.quickstart.generate.generation_quickstart` (``--photos DIR --generate``).
- ``train``: :func:`mitsuba_platonic.train.train` with a YAML config and ``--set`` overrides.
- ``evaluate``: :mod:`mitsuba_platonic.evaluate.report`, which declares its own flags.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from .args import CLIError, check_settings_once, positive_int

__all__ = ["add_quickstart", "add_train", "add_evaluate"]


def _cmd_quickstart(args: argparse.Namespace) -> int:
    if args.generate and args.photos is None:
        raise CLIError("--generate: it trains a generator on your photos; expected --photos DIR with it")
    fixed = {"run.steps": f"--steps {args.steps}"} if args.steps is not None else {}
    check_settings_once(args.set, fixed)
    if args.generate:
        from ..quickstart.generate import generation_quickstart

        report = generation_quickstart(Path(args.photos), Path(args.out or "quickstart-generate"), steps=args.steps,
                                       progress=not args.quiet, overrides=args.set or (), overwrite=args.overwrite)
    elif args.photos is not None:
        from ..quickstart.photos import photo_quickstart

        report = photo_quickstart(Path(args.photos), Path(args.out or "quickstart-photos"), steps=args.steps,
                                  progress=not args.quiet, overrides=args.set or (), overwrite=args.overwrite)
    else:
        from ..quickstart.procedural import quickstart

        report = quickstart(Path(args.out or "quickstart"), steps=args.steps, progress=not args.quiet,
                            overrides=args.set or (), overwrite=args.overwrite)
    text = report.read_text()
    print(text)
    print(f"report: {report}")
    if args.photos is not None:
        from ..evaluate.priors import warning_lines

        for line in warning_lines(text):                 # last, where it is seen: a round prior the photos contradict
            print(f"platonic quickstart: {line}")
    return 0


def add_quickstart(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("quickstart", help="the whole pipeline on a small procedural collection, or on your photos "
                                          "(--photos DIR) (CPU, minutes)",
                       description="Generate a small procedural collection, train single-image reconstruction "
                                   "at 32³ through the batched Mitsuba ray marcher (EA), reconstruct held-out images and "
                                   "write turntables, meshes and a report. With --photos DIR: train on your folder of "
                                   "cut-out photos instead and judge the held-out photos' reconstructions from every "
                                   "side. With --photos DIR --generate: train a generator of new objects of their "
                                   "class and judge its samples.")
    p.add_argument("--photos", default=None, metavar="DIR",
                   help="train on your own folder of cut-out photos of one class instead (configs/photos.yaml), and "
                        "judge the held-out photos' reconstructions from every side")
    p.add_argument("--generate", action="store_true",
                   help="with --photos: train a generator of new objects of the photos' class instead "
                        "(configs/photos_generate.yaml), judge its random samples against the held-out photos and "
                        "export 16 samples")
    p.add_argument("--out", default=None,
                   help="output folder (default: quickstart/, quickstart-photos/ with --photos, quickstart-generate/ "
                        "with --generate): new, empty or an earlier quickstart's, which it continues")
    p.add_argument("--overwrite", action="store_true",
                   help="write into an --out that holds files the quickstart did not write, replacing those of "
                        "its names (report.md, run/, data/, reconstructions/, samples/)")
    p.add_argument("--steps", type=positive_int, default=None, help="training steps (default: the config's)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a key of configs/quickstart.yaml (configs/photos.yaml with --photos, "
                        "configs/photos_generate.yaml with --generate), e.g. "
                        "model.resolution=16 (repeatable; of two settings of one key the later wins; --steps and "
                        "a --set of run.steps are refused together)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=_cmd_quickstart,
                   interrupted="nothing was written beyond what the folder held; run the same command again to "
                               "continue")


def _cmd_train(args: argparse.Namespace) -> int:
    from ..config import load_config
    from ..train import train

    cfg = load_config(args.config, args.set or ())
    config_file = Path(args.config) if args.config else None
    run_dir = train(cfg, resume=args.resume, progress=not args.quiet, config_file=config_file)
    if int(os.environ.get("RANK", "0")) == 0:             # one line, not one per torchrun process
        print(f"run: {run_dir}")
    return 0


def add_train(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("train", help="train PlatonicGAN from a config",
                       description="Train with a YAML config (configs/*.yaml); every key can be overridden "
                                   "with --set section.key=value. Writes a run folder with the resolved "
                                   "config, checkpoints, logs and samples (only into a new or empty folder or one of "
                                   "its own runs; the --config file is never written). Ctrl-C, SIGTERM or SIGHUP saves a "
                                   "checkpoint and ends the process by that signal (exit status 130, 143 or 129); "
                                   "--resume continues exactly. Data parallel: torchrun --nproc-per-node N "
                                   "-m mitsuba_platonic.cli train ...")
    p.add_argument("--config", default=None,
                   help="YAML config: a file, or a packaged config's name (e.g. paper, or configs/paper.yaml "
                        "where no such file is here) (default: the built-in defaults)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a config key (repeatable; of two settings of one key the later wins)")
    p.add_argument("--resume", action="store_true", help="continue the run from its last checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(handler=_cmd_train,
                   interrupted="no training step was saved beyond the run's last checkpoint, which is as it was; "
                               "run the same command again (with --resume if the run has a checkpoint)")


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from ..evaluate.report import run
    return run(args)


def add_evaluate(sub: "argparse._SubParsersAction") -> None:
    from ..evaluate.report import add_arguments
    p = sub.add_parser("evaluate", help="score trained runs as in the paper's Table 2 (docs/evaluation.md)",
                       description="Re-render held-out reconstructions and their ground truth (IF, VOL, ISO, "
                                   "VOX) under random skies, compare in 2D and 3D, and write report.md, "
                                   "figures and results.json. Runs trained on a photo folder get a real-photo "
                                   "section instead: held-out photos at the input view, novel views, front-card "
                                   "check.")
    add_arguments(p)
    p.set_defaults(handler=_cmd_evaluate,
                   interrupted="no report was written (report.md, results.json and the figures come at the end); "
                               "run the same command again")
