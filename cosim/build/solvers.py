"""C sources of the numerical solvers a native FMU links (:attr:`NativeSpec.solvers
<cosim.build.native.NativeSpec>`), taken at build time from the solver's published source
distribution on the package registry, never from this repository.

A solver is named by its Python distribution (:data:`SOLVERS`): the version installed in this
environment (``importlib.metadata.version``) is the one whose sdist is fetched, so a native
FMU runs the same solver release as the Python FMU it is compared with. The sdist is
downloaded once with pip (``python -m pip download <name>==<version> --no-deps --no-binary
:all:``) into the user cache (``$ATO_COSIM_CACHE`` or ``$XDG_CACHE_HOME/ato-cosim``, folder
``solvers``; a temporary folder when that cache is off), its SHA-256 is recorded beside it on
the first download and checked on every later use, and only the C files, headers and licence
(:attr:`SolverSource.sources`, :attr:`SolverSource.license`) are extracted from it. The FMU
ships them in ``sources/`` (compiled into its binaries with the project's floating-point
flags) and the licence in ``documentation/licenses/<name>-LICENSE.txt``.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import tarfile
import tempfile
import threading
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path, PurePosixPath

from cosim.fmu.disk_cache import cache_root


@dataclass(frozen=True)
class SolverSource:
    """A solver's C sources inside its registry sdist: the distribution ``package``, the
    folders of its C files and headers (``sources``, relative to the sdist's top folder;
    their ``*.c`` and ``*.h`` are taken, flat), its ``license`` file, and the C defines it is
    compiled with (``defines``; none: the solver's defaults)."""

    package: str
    sources: tuple[str, ...]
    license: str
    defines: tuple[str, ...] = ()

    @property
    def version(self) -> str:
        """The installed version of the distribution (the release whose sources are built)."""
        try:
            return metadata.version(self.package)
        except metadata.PackageNotFoundError as err:
            raise SolverUnavailable(
                f"the native build takes the C sources of {self.package!r} from its source "
                f"distribution at the installed version, but {self.package!r} is not "
                f"installed (python -m pip install {self.package})") from err

    def download_command(self, dest: Path) -> list[str]:
        """The pip command that fetches the sdist of the installed version into ``dest``."""
        return [sys.executable, "-m", "pip", "download", f"{self.package}=={self.version}",
                "--no-deps", "--no-binary", ":all:", "--disable-pip-version-check", "-d",
                str(dest)]


# DAQP (Arnström, Bemporad, Axehill: a dual active-set solver for embedded QP; MIT licence):
# its sdist holds csrc/src/*.c, csrc/include/*.h and LICENSE
SOLVERS = {"daqp": SolverSource("daqp", ("csrc/src", "csrc/include"), "LICENSE")}


class SolverUnavailable(RuntimeError):
    """A solver's source distribution cannot be obtained (not installed, download failed,
    checksum mismatch, unexpected content)."""


@dataclass(frozen=True)
class SolverFiles:
    """The extracted files of one solver release: C files and headers, and the licence."""

    name: str
    version: str
    sources: tuple[Path, ...]
    license: Path

    @property
    def license_name(self) -> str:
        """The licence's path inside an FMU."""
        return f"documentation/licenses/{self.name}-LICENSE.txt"


_LOCK = threading.Lock()  # parallel model builds (threads) share one download


def solver_cache() -> Path:
    """The folder holding the solvers' sdists and extracted sources."""
    root = cache_root()
    if root is None:  # the project cache is off: a per-user temporary folder
        return Path(tempfile.gettempdir()) / "ato-cosim-solvers"
    return root / "solvers"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _download(spec: SolverSource, folder: Path) -> Path:
    """The sdist of ``spec``'s installed version in ``folder`` (downloaded when absent),
    its SHA-256 checked against the one recorded at the first download."""
    version = spec.version
    archive = folder / f"{spec.package}-{version}.tar.gz"
    record = folder / f"{archive.name}.sha256"
    if not archive.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            cmd = spec.download_command(Path(tmp))
            done = subprocess.run(cmd, capture_output=True, text=True)
            found = sorted(Path(tmp).glob(f"{spec.package}-{version}.tar.gz")) + \
                sorted(Path(tmp).glob(f"{spec.package}-{version}.zip"))
            if done.returncode != 0 or not found:
                raise SolverUnavailable(
                    f"could not download the source distribution of {spec.package} {version} "
                    f"(its C sources are built into the native FMU); command: "
                    f"{' '.join(cmd)}\n{(done.stderr or done.stdout).strip()[-2000:]}")
            if found[0].suffix != ".gz":
                raise SolverUnavailable(f"{found[0].name}: expected a .tar.gz sdist")
            found[0].replace(archive)
    digest = _sha256(archive)
    if record.is_file():
        if record.read_text().split()[0] != digest:
            raise SolverUnavailable(
                f"{archive}: SHA-256 {digest} differs from the one recorded at its first "
                f"download ({record}); delete both to download it again")
    else:
        record.write_text(f"{digest}  {archive.name}\n")
    return archive


def solver_files(name: str) -> SolverFiles:
    """The C sources and licence of solver ``name`` (:data:`SOLVERS`) at its installed
    version, downloaded and extracted on first use. Raises :class:`SolverUnavailable` naming
    the package and the pip command when they cannot be obtained."""
    if name not in SOLVERS:
        raise ValueError(f"unknown solver {name!r}; known: {sorted(SOLVERS)}")
    spec = SOLVERS[name]
    version = spec.version
    folder = solver_cache() / f"{spec.package}-{version}"
    extracted = folder / "extracted"
    with _LOCK:
        if not (extracted / "files.txt").is_file():
            archive = _download(spec, folder)
            staging = Path(tempfile.mkdtemp(dir=folder, prefix=".extract-"))
            names: list[str] = []
            with tarfile.open(archive, "r:gz") as tar:
                for member in tar.getmembers():
                    parts = PurePosixPath(member.name).parts
                    if len(parts) < 2 or not member.isfile():
                        continue
                    inner = PurePosixPath(*parts[1:])  # below the sdist's top folder
                    wanted = (str(inner) == spec.license or
                              (str(inner.parent) in spec.sources and inner.suffix in (".c", ".h")))
                    if not wanted:
                        continue
                    target = staging / ("LICENSE" if str(inner) == spec.license else inner.name)
                    if target.exists():
                        raise SolverUnavailable(f"{archive}: two files named {inner.name}")
                    data = tar.extractfile(member)
                    target.write_bytes(data.read() if data is not None else b"")
                    if target.name != "LICENSE":
                        names.append(inner.name)
            if not (staging / "LICENSE").is_file() or not any(n.endswith(".c") for n in names):
                raise SolverUnavailable(f"{archive}: no {spec.license} or no C sources under "
                                        f"{', '.join(spec.sources)}")
            (staging / "files.txt").write_text("\n".join(sorted(names)) + "\n")
            if extracted.exists():
                import shutil

                shutil.rmtree(extracted)
            staging.replace(extracted)
    listed = (extracted / "files.txt").read_text().split()
    return SolverFiles(name, version, tuple(extracted / n for n in listed),
                       extracted / "LICENSE")
