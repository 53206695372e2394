"""The field member of a scene file (``field.safetensors``): its size, refused by its header before it is
inflated (and sized against the memory free: :mod:`.memory_guard`), and the checked
:class:`~pytest_n2r.field.grid.SceneField` decoded from it."""

from __future__ import annotations

import json
import zipfile
import zlib

from ..errors import SceneFileError
from ..field.grid import SceneField, n_sh_coefficients
from . import schema
from .archive import StoredMember
from .memory_guard import check_memory, decode_failure

__all__ = ["decode_field", "field_bytes", "field_limit"]

#: The most bytes a safetensors header may take (three tensors take under 300 bytes).
_MAX_TENSOR_HEADER_BYTES = 2**20


def field_bytes(resolution: int, data_bytes: int) -> int:
    """The peak bytes decoding a field takes (:meth:`~pytest_n2r.field.grid.SceneField.from_tensors`): per vertex
    of the ``resolution``³ grid, the occupancy, its bool copy and the used-vertex mask (a byte each) and the
    int32 row map; and four times the tensors' ``data_bytes`` (the inflated member, the loaded tensors, the
    float32 copy of the float16 values and the checks' temporaries)."""
    return 7 * resolution ** 3 + 4 * data_bytes


def field_limit(archive: zipfile.ZipFile, field_meta: dict, source: str) -> int:
    """The size of ``field.safetensors`` by its own header, once that is checked against the most the grid
    ``field_meta`` declares can take (the occupancy: one byte per cell; at most every vertex stored, an int64
    index and float16 values each). Only the header is read, so a member that would inflate to gigabytes
    is refused before it is. ``field_meta`` is checked first (:func:`~pytest_n2r.field.grid.check_field_metadata`)."""
    res, sh_degree = field_meta["resolution"], field_meta["sh_degree"]
    width = 1 + 3 * n_sh_coefficients(sh_degree)
    where = f"{source}: {schema.FIELD_FILE}"
    try:
        info = archive.getinfo(schema.FIELD_FILE)
        with archive.open(info) as fh:
            head = fh.read(8)
            length = int.from_bytes(head, "little") if len(head) == 8 else -1
            if not 2 <= length <= _MAX_TENSOR_HEADER_BYTES:
                raise SceneFileError(f"{where} is not a valid safetensors file (its header claims {length:,} "
                                     f"bytes; at most {_MAX_TENSOR_HEADER_BYTES:,} expected)")
            header = json.loads(fh.read(length))
    except KeyError:
        raise SceneFileError(f"{source}: the archive has no {schema.FIELD_FILE!r}") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, RuntimeError) as exc:
        raise SceneFileError(f"{source}: {schema.FIELD_FILE!r} is corrupt or truncated ({exc})") from None
    except (ValueError, RecursionError) as exc:
        raise SceneFileError(f"{where} is not a valid safetensors file (its header is not JSON: {exc})") from None
    if not isinstance(header, dict):
        raise SceneFileError(f"{where} is not a valid safetensors file (its header is not a JSON object)")
    try:
        end = max([int(entry["data_offsets"][1]) for name, entry in header.items() if name != "__metadata__"],
                  default=0)
    except (TypeError, KeyError, IndexError, ValueError):
        raise SceneFileError(f"{where} is not a valid safetensors file (a tensor without data_offsets)") from None
    total = 8 + length + end
    if end > (res - 1) ** 3 + res ** 3 * (8 + 2 * width):  # names, shapes, dtypes: checked once loaded
        raise SceneFileError(f"{where}: its tensors claim {end:,} bytes, more than the declared {res}³ grid of "
                             f"SH degree {sh_degree} can hold; the file is corrupt or not written by `n2r fit`")
    check_memory(field_bytes(res, total), where, f"the {res}³ grid of {schema.SCENE_JSON} field.resolution")
    return total


def decode_field(stored: StoredMember, field_meta: dict, source: str) -> SceneField:
    """The field of a scene file from its stored ``field.safetensors`` member, checked."""
    import safetensors
    import safetensors.torch

    try:
        tensors = safetensors.torch.load(stored.inflate())
        return SceneField.from_tensors(field_meta, tensors, f"{source}: {schema.FIELD_FILE}")
    except safetensors.SafetensorError as exc:
        raise SceneFileError(f"{source}: {schema.FIELD_FILE} is not a valid safetensors file ({exc})") from None
    except (MemoryError, RuntimeError) as exc:  # torch's allocator: "DefaultCPUAllocator: can't allocate memory"
        raise decode_failure(exc, f"{source}: {schema.FIELD_FILE}",
                             f"the field declared in {schema.SCENE_JSON} does not fit in the memory free",
                             "the file is corrupt or not written by `n2r fit`") from None
