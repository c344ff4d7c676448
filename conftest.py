"""Setup shared by the tests of every package (pytest loads this root conftest first)."""
import signal

# A job that a non-interactive shell starts in the background (`cmd &`, some CI runners)
# inherits SIGINT as ignored, and so would every process a test starts: neither `ros2 run`
# nor the nodes would react to the Ctrl-C that several tests send, and those tests would
# time out and leave their nodes running. A caught signal is reset to the default in a child
# at exec (an ignored one is not), so catching it here gives every child a normal SIGINT.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
