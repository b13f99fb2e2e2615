"""Files the package ships for users who installed it with pip instead of cloning the repository:
the example trainer configs (the checkout's ``configs/``) and the Slurm job template with its sweep
helper (the checkout's ``docker/slurm/``). In the checkout ``configs`` and ``slurm`` here are
symbolic links to those folders, so each file exists once; a wheel holds copies
(pyproject.toml's package-data). ``mlagents-like-learn --list-configs``, ``--copy-configs DIR`` and
``--write-slurm-template DIR`` (trainer/config/cli_args.py) call the functions below.
"""
from __future__ import annotations

import shutil
import sys
from importlib import resources
from pathlib import Path

SLURM_FILES = ("train.sbatch", "sweep.sh", "sweep.py")


def _folder(name: str) -> Path:
    return Path(str(resources.files(__name__) / name))


def config_paths() -> list[Path]:
    """The shipped trainer configs (``*.yaml``), by name."""
    return sorted(_folder("configs").glob("*.yaml"))


def _copy(sources: list[Path], destination: str | Path) -> list[Path]:
    """Copy ``sources`` into ``destination`` (created if missing), keeping their permission bits;
    FileExistsError naming the first file already there: nothing of the user's is overwritten."""
    folder = Path(destination)
    folder.mkdir(parents=True, exist_ok=True)
    targets = [folder / source.name for source in sources]
    existing = [target for target in targets if target.exists()]
    if existing:
        raise FileExistsError(f"{existing[0]} exists already; remove it or choose another folder")
    for source, target in zip(sources, targets):
        shutil.copy2(source, target)
    return targets


def copy_configs(destination: str | Path) -> list[Path]:
    return _copy(config_paths(), destination)


def write_slurm_template(destination: str | Path) -> list[Path]:
    return _copy([_folder("slurm") / name for name in SLURM_FILES], destination)


def slurm_usage(folder: Path) -> str:
    """How to submit the written template with this installation's Python environment."""
    return (f"submit with:  MLAGENTS_LIKE_VENV={sys.prefix} sbatch {folder / 'train.sbatch'} CONFIG.yaml "
            "[mlagents-like-learn arguments]   (docs/cluster.md, or the comments at the top of train.sbatch)")
