"""Guards shared by the tests (imported as a plain module, like paths.py)."""
import contextlib
import signal


@contextlib.contextmanager
def deadline(seconds):
    """Fail (instead of hanging the suite) when the block takes longer than ``seconds``: for
    tests of inputs that once blocked (a FIFO, /dev/zero, an alias bomb)."""
    def boom(*_):
        raise TimeoutError(f"took longer than {seconds} s")
    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
