"""Command-line arguments the benchmark scripts share (imported as ``_arguments``: scripts run from this folder)."""

from __future__ import annotations

import argparse

from pytest_n2r.cli.fit import build_config, parse_config_override
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.config import FieldConfig


def field_config(parser: argparse.ArgumentParser, texts: list[str]) -> tuple[FieldConfig, set[str]]:
    """The default :class:`FieldConfig` with ``--config KEY=VALUE`` ``texts`` applied, as ``n2r fit --config``
    applies them, and the keys given; a malformed pair, an unknown key or a bad value ends as ``parser``'s usage
    error naming it (exit 2), before any work."""
    try:
        pairs = [parse_config_override(text) for text in texts]
        return build_config(pairs), {key for key, _ in pairs}
    except (argparse.ArgumentTypeError, InvalidArgument) as exc:
        parser.error(str(exc))
