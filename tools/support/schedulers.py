"""The `--scheduler ADDRESS` option of the tools that run tasks on Dask (envelope, train): an
address Dask cannot parse stops argparse, naming the option and the value, exit code 2."""

from __future__ import annotations

import argparse


def scheduler_address(text: str) -> str:
    """A Dask scheduler address with a host and a port (tcp://host:8786), for argparse; parsed by
    Dask itself, which is imported only when the option is given."""
    from distributed.comm.addressing import get_address_host_port

    try:
        get_address_host_port(text)
    except ValueError:
        wanted = "a Dask scheduler address such as tcp://host:8786"
        raise argparse.ArgumentTypeError(f"wants {wanted}, got {text!r}") from None
    return text


scheduler_address.__name__ = "address"  # argparse names the type in its messages
