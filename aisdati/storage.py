"""Model folders at a URL: `aisdati train --out s3://bucket/models`, `detect --models ...`.

A Dask cluster of several machines has no folder they all see; object stores and file servers
are where such a cluster keeps what its tasks write. Any fsspec URL works (`s3://` with s3fs,
`gs://` with gcsfs, `abfs://` with adlfs, `ftp://`, `sftp://` with paramiko, `file://`); the
package of a protocol is the user's to install, and its absence is one line naming it.

The model code writes and reads local files only. A training task whose settings carry a URL
(`TrainSettings.publish_to`) trains into a local folder of its own on whatever machine runs it
and then copies the model there (`RemoteFolder.publish`): the old card is removed first and
the new one copied last, under a temporary name and renamed, so that a reader, who finds models
by their cards, never loads new weights with an old card or a half-copied card. Commands that
judge with models fetch a folder's models into a local temporary folder first
(`fetched_models`); checkpoints (`.ckpt`) stay where they are, as they serve only `--resume`,
which needs a local `--out`.
"""

from __future__ import annotations

import os
import re
import tempfile
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aisdati.errors import UserError

URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")
CARD_SUFFIX = ".json"
PROCESS_LOCAL = ("memory",)
"""fsspec protocols whose files live in the process that wrote them: a model "written" there is
gone when the command exits, so they are refused as model folders."""
NOT_COPIED = (".ckpt",)
"""Files of a model that are neither published nor fetched (checkpoints: only `--resume` reads
them, in a local folder)."""


def without_password(url: str) -> str:
    """`url` as messages show it: its password (`user:PW@`, `password=PW`) replaced by `***`,
    so that no error, progress line or log holds it."""
    url = re.sub(r"(://[^/:@]+):[^/]*@", r"\1:***@", url)
    return re.sub(r"(?i)([?&]password=)[^&#]*", r"\1***", url)


def is_url(text: str | os.PathLike[str]) -> bool:
    """Whether a folder option names a URL (`scheme://...`) rather than a local path."""
    return isinstance(text, str) and bool(URL.match(text))


@dataclass(frozen=True)
class RemoteFolder:
    """A folder at an fsspec URL, named by the option that gave it (for its errors)."""

    url: str
    option: str = "--out"

    def filesystem(self) -> tuple[Any, str]:
        """(the fsspec filesystem, the folder's path in it); a protocol fsspec does not know or
        whose package is missing is a one-line `UserError`."""
        import fsspec

        if self.scheme in PROCESS_LOCAL:
            raise UserError(
                f"{self.option} {self.shown}: {self.scheme}:// keeps files only while this "
                "command runs; give a folder or a URL that outlives it"
            )
        try:
            fs, root = fsspec.core.url_to_fs(self.url)
        except ImportError as exc:
            raise UserError(
                f"{self.option} {self.shown}: {self.scheme}:// needs a package that is not "
                f"installed ({first_line(exc)})"
            ) from None
        except ValueError as exc:
            raise UserError(f"{self.option} {self.shown}: {first_line(exc)}") from None
        except Exception as exc:  # backends that connect at once (ftp, sftp): refused, no host
            reason = first_line(exc)
            raise UserError(f"{self.option} {self.shown}: cannot connect: {reason}") from None
        return fs, root.rstrip("/")

    @property
    def scheme(self) -> str:
        return self.url.split("://", 1)[0].lower()

    @property
    def shown(self) -> str:
        """The URL without a password, for messages."""
        return without_password(self.url)

    def join(self, name: str) -> str:
        """The URL of `name` in this folder without its password: what a model's
        `Trained.model` reports, and the summary and `--json` print."""
        return self.shown.rstrip("/") + "/" + name

    def check_writable(self) -> None:
        """Create the folder and write and remove a probe file, so that a training run learns
        of a wrong address or missing rights before its first episode, not after its last."""
        fs, root = self.filesystem()
        probe = f"{root}/.aisdati-write-test.{uuid.uuid4().hex}.tmp"
        with self.errors("cannot write there"):
            fs.makedirs(root, exist_ok=True)
            fs.pipe_file(probe, b"")
            fs.rm_file(probe)

    def publish(self, files: Sequence[Path]) -> None:
        """Copy one model's local files here (but its checkpoint, `NOT_COPIED`): its old card
        removed first, its new card last and renamed into place (module docstring)."""
        files = [f for f in files if not f.name.endswith(NOT_COPIED)]
        cards = [f for f in files if f.name.endswith(CARD_SUFFIX)]
        rest = [f for f in files if not f.name.endswith(CARD_SUFFIX)]
        fs, root = self.filesystem()
        with self.errors("cannot copy the model there"):
            fs.makedirs(root, exist_ok=True)
            for card in cards:
                if fs.exists(f"{root}/{card.name}"):
                    fs.rm_file(f"{root}/{card.name}")
            for f in rest:
                fs.put_file(str(f), f"{root}/{f.name}")
            for card in cards:
                part = f"{root}/.{card.name}.{uuid.uuid4().hex}.tmp"
                fs.put_file(str(card), part)
                fs.mv(part, f"{root}/{card.name}")

    def fetch(self, into: Path, names: Sequence[str]) -> None:
        """Copy the models named (every model when `names` is empty) into the local `into`."""
        fs, root = self.filesystem()
        with self.errors("cannot read it"):
            listed = [e for e in fs.ls(root, detail=True) if e.get("type") == "file"]
        files = {Path(e["name"]).name: e["name"] for e in listed}
        stems = list(names) or [n[: -len(CARD_SUFFIX)] for n in files if is_card(n)]
        if not stems:
            raise UserError(f"no models at {self.shown}: run `aisdati train --out {self.shown}`")
        for stem in stems:
            if stem + CARD_SUFFIX not in files:
                raise UserError(f"no model {stem!r} at {self.shown} (no {stem}{CARD_SUFFIX})")
        wanted = [
            n for n in files
            if any(n.startswith(s + ".") for s in stems) and not n.endswith(NOT_COPIED)
        ]  # fmt: skip
        with self.errors("cannot read it"):
            for name in wanted:
                fs.get_file(files[name], str(into / name))

    @contextmanager
    def errors(self, doing: str) -> Iterator[None]:
        """Turn the filesystem's errors (unreachable host, refused login, no such bucket) into
        one line naming the URL."""
        try:
            yield
        except UserError:
            raise
        except Exception as exc:  # fsspec backends raise their own types (ftplib, botocore)
            raise UserError(f"{self.option} {self.shown}: {doing}: {first_line(exc)}") from None


def is_card(name: str) -> bool:
    """A model card's file name (a training log, `<stem>.log.jsonl`, is not one)."""
    return name.endswith(CARD_SUFFIX) and not name.startswith(".")


def first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def shown_folder(folder: str | Path | None) -> str | None:
    """How messages name a model folder given as `folder`: a URL without its password; None
    for a local path (named as it is) or no folder."""
    return RemoteFolder(str(folder)).shown if folder and is_url(str(folder)) else None


@contextmanager
def fetched_models(folder: str | Path, names: Sequence[str], option: str) -> Iterator[Path]:
    """The local folder holding the models of `folder`: itself for a path; for a URL, a
    temporary copy of its models (removed on leaving)."""
    if not is_url(str(folder)):
        yield Path(folder)
        return
    with tempfile.TemporaryDirectory(prefix="aisdati-models-") as tmp:
        RemoteFolder(str(folder), option).fetch(Path(tmp), names)
        yield Path(tmp)


@contextmanager
def staging_folder() -> Iterator[Path]:
    """A local folder a training task writes its models into before publishing them."""
    with tempfile.TemporaryDirectory(prefix="aisdati-train-") as tmp:
        yield Path(tmp)
