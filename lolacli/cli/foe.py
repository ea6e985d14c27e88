"""`lolacli foe …`: firmware download (write) and upload (read) over FoE.

Thin: options -> :class:`lolacli.sdo.session.TransportOptions` (the transports of ``sdo``,
its options defined once in :mod:`lolacli.cli.sdo`), one call of
:mod:`lolacli.sdo.foe`, render. The slave goes to BOOT for the transfer and back to INIT
after it. Exit 1 when the slave answers with an FoE error, 4 when the bus does not answer
or the slave refuses BOOT.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json, wrapped
from lolacli.cli.options import EniOption, EsiOption, IfaceOption
from lolacli.cli.sdo import BackendOption, SlaveArgument

SCHEMA = "lolacli.foe/1"
MAX_WRITE_BYTES = 256 * 1024 * 1024  # read whole into memory before the transfer

app = typer.Typer(
    no_args_is_help=True,
    help="FoE firmware download (write) and upload (read), the slave in BOOT with its "
    "bootstrap mailbox: lolacli's master (the emulated chain in process by default, --iface "
    "IF for a live bus) or pysoem (--iface IF --backend soem).",
)

PasswordOption = Annotated[
    str,
    typer.Option(
        "--password",
        "-p",
        metavar="N",
        help="The file's FoE password: 32-bit unsigned, decimal or 0x hex.",
    ),
]
TimeoutOption = Annotated[
    float,
    typer.Option("--timeout", min=0.001, max=3600.0, help="Seconds to wait for each answer."),
]


def _password(text: str) -> int:
    try:
        value = int(text.strip(), 0)
    except ValueError:
        raise typer.BadParameter(f"{text!r} is not a number", param_hint="--password") from None
    if not 0 <= value <= 0xFFFF_FFFF:
        raise typer.BadParameter(f"{text} is not 32-bit unsigned", param_hint="--password")
    return value


def _options(
    iface: str | None, backend: str, eni: Path | None, esi: list[Path] | None, timeout: float
) -> Any:
    from lolacli.sdo.session import TransportOptions

    return TransportOptions(
        iface=iface, backend=backend, eni=eni, esi=tuple(esi or ()), timeout_s=timeout
    )


def _run(fmt: OutputFormat, base: dict[str, Any], call: Any) -> Any:
    """``call()``; an FoE error or a bus failure as the JSON error document too."""
    from lolacli.errors import FoeError, TransportError, UsageError

    try:
        return call()
    except (FoeError, TransportError, UsageError) as exc:
        if fmt is not OutputFormat.json or isinstance(exc, UsageError):
            raise
        code = f"0x{exc.code:04X}" if isinstance(exc, FoeError) and exc.code is not None else None
        emit_json({"schema": SCHEMA, **base, "error": {"code": code, "message": str(exc)}})
        raise typer.Exit(exc.exit_code) from None


def _say(result: Any, verb: str, path: Path) -> None:
    """Three lines, each fitted to the terminal (80 columns when piped)."""

    from lolacli.text import number, plural

    size = plural(result.bytes, "byte")
    rate = result.bytes / result.seconds / 1024 if result.seconds > 0 else 0.0
    how = [number(result.seconds, "s", 2), number(rate, "KiB/s", 1)]
    if result.packets is not None:
        how.insert(0, plural(result.packets, "packet"))
    if result.busy:
        how.insert(1, f"{result.busy} busy")
    lines = [
        f"slave {result.slave}: {verb} {result.name!r}, {size}",
        f"  {', '.join(how)} ({result.backend}); slave back in INIT",
        f"  file {path}",
    ]
    out = [w for line in lines for w in wrapped(line)]
    sys.stdout.write("".join(line + "\n" for line in out))


def _document(result: Any, path: Path, data: bytes) -> dict[str, Any]:
    return {
        "schema": SCHEMA,
        **result.to_dict(),
        "file": str(path),
        "sha256": hashlib.sha256(data).hexdigest(),
    }


@app.command("write")
def write_cmd(
    slave: SlaveArgument,
    file: Annotated[
        Path, typer.Argument(help="The file to download (a firmware).", show_default=False)
    ],
    name: Annotated[
        str | None,
        typer.Option("--name", help="The file's name on the slave (default: FILE's name)."),
    ] = None,
    password: PasswordOption = "0",
    iface: IfaceOption = None,
    backend: BackendOption = "lolacli",
    eni: EniOption = None,
    esi: EsiOption = None,
    timeout: TimeoutOption = 1.0,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Download FILE to the slave over FoE (firmware update), the slave in BOOT."""
    from lolacli.errors import InputError
    from lolacli.sdo.foe import open_foe

    key = _password(password)
    try:
        with open(file, "rb") as f:  # a device file (/dev/zero) ends at the limit
            data = f.read(MAX_WRITE_BYTES + 1)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", path=str(file)) from None
    if len(data) > MAX_WRITE_BYTES:
        raise InputError(f"larger than {MAX_WRITE_BYTES:,} bytes: not a firmware", path=str(file))
    target_name = name if name is not None else file.name
    base = {"slave": slave, "direction": "write", "name": target_name}

    def call() -> Any:
        with open_foe(_options(iface, backend, eni, esi, timeout)) as session:
            return session.target(slave).write(target_name, data, key)

    result = _run(fmt, base, call)
    if fmt is OutputFormat.json:
        emit_json(_document(result, file, data))
        return
    _say(result, "wrote", file)


@app.command("read")
def read_cmd(
    slave: SlaveArgument,
    name: Annotated[str, typer.Argument(help="The file's name on the slave.", show_default=False)],
    output: Annotated[
        Path,
        typer.Option("--output", "-o", help="Where to write the file read.", show_default=False),
    ],
    password: PasswordOption = "0",
    max_size: Annotated[
        int,
        typer.Option("--max-size", min=1, help="Bytes the file may have at most."),
    ] = 16 * 1024 * 1024,
    iface: IfaceOption = None,
    backend: BackendOption = "lolacli",
    eni: EniOption = None,
    esi: EsiOption = None,
    timeout: TimeoutOption = 1.0,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Upload the slave's file NAME over FoE into -o FILE, the slave in BOOT."""
    from lolacli.errors import UsageError
    from lolacli.sdo.foe import open_foe

    key = _password(password)
    base = {"slave": slave, "direction": "read", "name": name}

    def call() -> Any:
        with open_foe(_options(iface, backend, eni, esi, timeout)) as session:
            return session.target(slave).read(name, key, max_bytes=max_size)

    data, result = _run(fmt, base, call)
    try:
        output.write_bytes(data)
    except OSError as exc:
        raise UsageError(f"cannot write {output}: {exc.strerror or exc}") from None
    if fmt is OutputFormat.json:
        emit_json(_document(result, output, data))
        return
    _say(result, "read", output)
