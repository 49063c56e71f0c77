"""Persisted EEPROM areas: one JSON file per servo slot, written atomically.

Why it exists: a real servo keeps its ID, baud, limits across power cycles;
``ax12emu serve --state-dir DIR`` does the same.  A servo is keyed by the ID
it was launched with (its slot), so a servo launched as ``--ids 1`` whose ID
a client changed to 5 comes back as 5 when launched as ``--ids 1`` again.

Files hold register values by name (readable, diffable) and are replaced
atomically (temporary file, fsync, rename), so a crash mid-write leaves the
old or the new state, never a mix.  Names are built only from integers, so
no input can make the store touch a file outside its directory, and a state
file that is a symlink is refused rather than followed.  A file also keeps
its servo's model number: another model launched on the same slot (Protocol 2.0
buses mix models, each with its own EEPROM layout) is refused with a message
rather than given an image that is not its own.  A Protocol 2.0 servo's Control
Table Backup is kept beside its EEPROM (the table's bytes as stored, in hex): the
servo keeps it in its own non-volatile memory, and Startup Configuration's RAM
Restore reads it at power-up.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import stat
import tempfile
from pathlib import Path
from typing import Protocol

from ax12emu.protocol.control_table import Access, Area
from ax12emu.protocol.registers import Layout, Profile

__all__ = ["PersistentTable", "StateStore", "StateFileError"]

log = logging.getLogger(__name__)

#: The file a serving process holds locked while it keeps its servos' state in the directory.
LOCK_NAME = "lock"
#: Every state file's "format": a JSON file of another kind is refused, not read for the keys it happens to share.
FORMAT = "ax12emu-eeprom/1"


class PersistentTable(Protocol):
    """What the store needs of a control table: the AX-12's ``ControlTable`` and the Protocol 2.0 ``Table2`` both are one."""

    layout: Layout

    @property
    def profile(self) -> Profile: ...

    def get(self, name: str) -> int: ...

    def eeprom_bytes(self) -> bytes: ...

    def load_eeprom(self, data: bytes) -> None: ...


class StateFileError(ValueError):
    """A state file exists but cannot be used; the message names the file."""


def _open_regular(path: Path, flags: int, mode: int = 0o644) -> int:
    """``os.open`` of a regular file; OSError for anything else.  O_NONBLOCK: a named pipe in its place blocked the
    open (and the server's start, before it printed its port) until something wrote to it."""
    fd = os.open(path, flags | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0), mode)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    os.set_blocking(fd, True)
    return fd


def _document(path: Path) -> dict:
    """A state file's JSON object; ValueError (or OSError, RecursionError) where it is not one of this format.

    O_NOFOLLOW: a symlink planted in the directory cannot make the store read a file elsewhere (ELOOP, reported
    as an unusable state file).
    """
    fd = _open_regular(path, os.O_RDONLY)
    with os.fdopen(fd, encoding="utf-8") as handle:
        document = json.loads(handle.read())
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise ValueError(f"not an {FORMAT} file")
    return document


class StateStore:
    """Reads and writes the EEPROM image of each servo slot under ``directory``."""

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise StateFileError(f"{self.directory}: exists and is not a folder (a state directory holds one file per servo)")
        self.directory.mkdir(parents=True, exist_ok=True)
        self._lock_fd: int | None = None
        #: Slots whose last save failed (said once each, until one succeeds).
        self._failing: set[int] = set()
        #: Slot -> the servo's own ID while its ID register shows another (a fault's duplicate): a fault is not
        #: the servo's configuration, so what is kept is the ID it had.
        self.own_ids: dict[int, int] = {}

    def claim(self) -> None:
        """Take the directory for this process, one server per state directory as one servo per EEPROM; a
        :class:`StateFileError` naming the holder's pid if another process has it.

        Why: two servers on one directory overwrote each other's files, and the second one's start removed the
        first's temporary file mid-save, which killed it.  The lock is the kernel's (``flock``), so a server that
        crashed holds nothing.  Once claimed, the temporary files a crash left between writing and renaming (the
        state file itself intact) are removed so they do not pile up.
        """
        if self._lock_fd is not None:
            return
        path = self.directory / LOCK_NAME
        fd = _open_regular(path, os.O_RDWR | os.O_CREAT)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise StateFileError(f"{self.directory}: in use by another server (pid {holder}); "
                                 "one server per state directory") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd = fd
        for leftover in self.directory.glob("servo-[0-9][0-9][0-9].json*.tmp"):
            leftover.unlink(missing_ok=True)

    def release(self) -> None:
        """Give the directory up (a process's exit does too)."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def save_or_say(self, slot: int, table: PersistentTable, backup: bytes | None = None) -> bool:
        """:meth:`save`, for a server mid-session: a failure (the directory removed, made read-only, a full disk)
        is logged, once until a save of that slot succeeds again, and the server goes on serving; the servo's
        EEPROM stays as written, only not kept.  False if it failed."""
        try:
            self.save(slot, table, backup)
        except OSError as exc:
            if slot not in self._failing:
                self._failing.add(slot)
                log.error("could not keep the EEPROM of the servo launched as ID %d in %s (%s); serving on, "
                          "but that change will not survive a restart", slot, self.directory, exc)
            return False
        self._failing.discard(slot)
        return True

    def path_for(self, slot: int) -> Path:
        """The file of the servo launched with ID ``slot``."""
        if not 0 <= int(slot) <= 0xFD:
            raise ValueError(f"servo slot must be 0..253, got {slot}")
        return self.directory / f"servo-{int(slot):03d}.json"

    def load(self, slot: int, table: PersistentTable) -> bool:
        """Load the slot's EEPROM into ``table``; False if there is no file yet."""
        path = self.path_for(slot)
        if not path.exists():
            return False
        try:
            document = _document(path)
            registers = document["eeprom"]
            if not isinstance(registers, dict):
                raise TypeError("'eeprom' must be an object")
            saved_model = document.get("model_number")
            if saved_model is not None and (not isinstance(saved_model, int) or isinstance(saved_model, bool)):
                raise TypeError(f"model_number must be an integer, got {saved_model!r}")
            if saved_model is not None and saved_model != table.get("model_number"):
                raise StateFileError(
                    f"{path}: holds the EEPROM of another model ({document.get('profile', '?')}, model number {saved_model}), "
                    f"not {table.profile.name} (model number {table.get('model_number')}); the servo launched with ID {slot} "
                    "is another model now: remove the file, give the state its own --state-dir, or start with --factory-reset")
            image = bytearray(table.eeprom_bytes())
            for entry in table.layout.entries:
                if entry.area is Area.EEPROM and entry.access is Access.RW and entry.name in registers:
                    value = registers[entry.name]
                    if not isinstance(value, int) or isinstance(value, bool):
                        raise TypeError(f"{entry.name} must be an integer, got {value!r}")
                    low, high = entry.byte_range
                    if not low <= value <= high:
                        raise ValueError(f"{entry.name} = {value} does not fit in {entry.size} byte(s)")
                    image[entry.address : entry.end] = entry.to_bytes(value)
            table.load_eeprom(bytes(image))
        except StateFileError:
            raise
        except (OSError, ValueError, TypeError, KeyError, RecursionError) as exc:
            raise StateFileError(f"{path}: unusable state file ({exc}); remove it or start with --factory-reset") from exc
        return True

    def load_backup(self, slot: int, size: int) -> bytes | None:
        """The slot's Control Table Backup (``size`` bytes: the table's), or None where none was stored."""
        path = self.path_for(slot)
        if not path.exists():
            return None
        try:
            text = _document(path).get("backup")
            if text is None:
                return None
            if not isinstance(text, str):
                raise TypeError(f"'backup' must be a hex string, got {type(text).__name__}")
            backup = bytes.fromhex(text)
            if len(backup) != size:
                raise ValueError(f"the backup holds {len(backup)} bytes, the table {size}")
        except (OSError, ValueError, TypeError, RecursionError) as exc:
            raise StateFileError(f"{path}: unusable state file ({exc}); remove it or start with --factory-reset") from exc
        return backup

    def save(self, slot: int, table: PersistentTable, backup: bytes | None = None) -> None:
        """Write the slot's EEPROM (and its Control Table Backup, if any) atomically."""
        registers = {
            entry.name: table.get(entry.name)
            for entry in table.layout.entries
            if entry.area is Area.EEPROM and entry.access is Access.RW
        }
        if slot in self.own_ids:
            registers["id"] = self.own_ids[slot]
        # The model number keys the image to its model: a different model started on the same ID (a
        # Protocol 2.0 bus mixes models, each with its own EEPROM layout) must not take it for its own.
        document = {"format": FORMAT, "profile": table.profile.name, "model_number": table.get("model_number"),
                    "eeprom": registers}
        if backup is not None:
            document["backup"] = backup.hex()
        path = self.path_for(slot)
        fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=self.directory)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as handle:
                json.dump(document, handle, indent=1, sort_keys=True)
                handle.write("\n")
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        dir_fd = os.open(self.directory, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)

