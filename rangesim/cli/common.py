"""Helpers shared by the command modules: output checks and write-error reporting."""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from rangesim.core.errors import RangesimError


def check_suffix(path: Path, allowed: Sequence[str], what: str) -> None:
    """Reject an output extension before any work is done."""
    if path.suffix.lower() not in allowed:
        found = f"{path.suffix!r} files" if path.suffix else "files without an extension"
        raise RangesimError(
            f"cannot write {what} as {found}; supported: {', '.join(allowed)}", source=path
        )


@contextmanager
def writing(path: Path, tmp: Path | None = None) -> Iterator[None]:
    """Report a failed write against ``path``, not the temporary name the data went to."""
    try:
        yield
    except OSError as exc:
        reason = exc.strerror or str(exc)
        # mkdir under a regular file says "File exists" or "Not a directory": name the culprit
        blocker = next((p for p in path.parents if p.exists()), None)
        if blocker is not None and not blocker.is_dir():
            reason = f"{blocker} is not a directory"
        raise RangesimError(f"cannot write file ({reason})", source=path) from exc
    except RangesimError as exc:
        if tmp is None or str(tmp) not in str(exc):
            raise
        relabelled = RangesimError(str(exc).replace(str(tmp), str(path)))
        relabelled.source = str(path)
        raise relabelled from exc


def build_model(name: str, param_texts: Sequence[str]):
    """A built-in CAD model from its name and ``--param KEY=VALUE`` texts (TOML values)."""
    import tomllib

    from rangesim.cad.models import MODELS, model_names

    if name not in MODELS:
        raise RangesimError(f"unknown model; built-in models: {', '.join(model_names())}", source=name)
    params = {}
    for text in param_texts:
        key, sep, raw = text.partition("=")
        if not sep:
            raise RangesimError(f"--param expects KEY=VALUE, got {text!r}")
        try:
            params[key.strip()] = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError as exc:
            raise RangesimError(f"--param {key}: not a TOML value: {raw!r}") from exc
    return MODELS[name](**params)
