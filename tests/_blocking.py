"""A time guard for calls that could block reading a FIFO: a regression fails its test instead of
hanging the suite."""

from __future__ import annotations

import os
import threading

import pytest


def raised_within(call, fifos=(), seconds: float = 20.0) -> BaseException:
    """The exception ``call()`` raises within ``seconds``. A call still running then (blocked in
    ``open`` or ``read`` of a FIFO) fails the test; its reader is released by opening ``fifos``
    for writing. A call that returns fails the test too."""
    out: list[BaseException | None] = []

    def run():
        try:
            call()
            out.append(None)
        except BaseException as e:  # handed to the test
            out.append(e)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        for f in fifos:  # release a reader blocked in open() or read()
            try:
                os.close(os.open(f, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:
                pass
        thread.join(5)
        pytest.fail(f"the call blocked for {seconds} s instead of refusing the special file")
    assert out and out[0] is not None, "the call returned instead of refusing"
    return out[0]
