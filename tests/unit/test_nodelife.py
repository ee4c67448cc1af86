"""StopSignals in a process of its own: real signals, sent in bursts; Interrupts held while rospy registers."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from comm.nodelife import Interrupts, registering

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

_BURST = textwrap.dedent("""
    import os, subprocess, sys
    from comm.nodelife import StopSignals, stop_requested

    stop = StopSignals()
    # another process, so the signals keep coming while the handler runs
    sender = subprocess.Popen([sys.executable, "-c", "import os, signal\\n"
                              "while True: os.kill(%%d, signal.SIG%s)" %% os.getpid()])
    stop.wait()
    sender.kill()
    sender.wait()  # Python restores the default handlers as it exits
    print("stopped by", stop.signal, stop_requested(), flush=True)
""")


def _run(script: str) -> subprocess.CompletedProcess:
    try:
        return subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=20)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError("the process did not stop: %s" % exc.stderr) from None


def test_a_burst_of_sigterm_stops_the_wait():
    """A parent killed with many threads sends its pdeathsig once per ending thread; a handler
    that took a lock deadlocked on itself (the Blackboard node stayed alive, orphaned)."""
    out = _run(_BURST % "TERM")
    assert out.returncode == 0 and "stopped by 15 True" in out.stdout, out.stderr


def test_a_burst_of_sigint_stops_the_wait():
    out = _run(_BURST % "INT")
    assert out.returncode == 0 and "stopped by 2 True" in out.stdout, out.stderr


def test_a_wake_from_another_thread_stops_the_wait():
    """rospy's shutdown hook (master kicked the node out) runs in another thread."""
    out = _run(textwrap.dedent("""
        import threading
        from comm.nodelife import StopSignals

        stop = StopSignals()
        threading.Timer(0.2, stop._wake).start()
        stop.wait()
        print("woken", stop.signal, stop.requested, flush=True)
    """))
    assert out.returncode == 0 and "woken None True" in out.stdout, out.stderr


def test_a_signal_taken_by_another_thread_stops_the_wait():
    """The kernel gives a process-wide signal to whichever thread takes it; here the main thread
    blocks SIGTERM, so another one must. Python runs the handler in the main thread only, and
    only once that thread wakes up."""
    out = _run(textwrap.dedent("""
        import os, signal, subprocess, sys, threading, time
        from comm.nodelife import StopSignals

        stop = StopSignals()
        threading.Thread(target=time.sleep, args=(60,), daemon=True).start()  # SIGTERM not blocked here
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
        subprocess.Popen([sys.executable, "-c", "import os, time\\ntime.sleep(0.3)\\nos.kill(%d, 15)" % os.getpid()])
        stop.wait()
        print("stopped by", stop.signal, flush=True)
    """))
    assert out.returncode == 0 and "stopped by 15" in out.stdout, out.stderr


def test_the_shutdown_hook_wakes_rospys_registration_thread(monkeypatch):
    """``rospy.signal_shutdown`` joins the RegManager's thread, which otherwise sees the
    shutdown only at its next half-second poll: every node took 0.6 s to stop."""
    import threading

    import rospy.core
    from rospy.impl.registration import RegManager

    from comm.nodelife import _wake_registration_thread

    monkeypatch.setattr(rospy.core, "_preshutdown_hooks", [])
    manager = RegManager(handler=None)  # registers its cleanup as a pre-shutdown hook, as in a node
    waiting, woken = threading.Event(), threading.Event()

    def registration_thread():
        with manager.cond:
            waiting.set()
            manager.cond.wait()  # no timeout: only a notify ends it (the hook takes the lock after this wait)
        woken.set()

    hook = _wake_registration_thread()
    threading.Thread(target=registration_thread, daemon=True).start()
    assert waiting.wait(10)
    hook("signal-2")
    assert woken.wait(10), "the registration thread was not woken"


def _stopped_without_a_master(tmp_path, *args: str) -> subprocess.CompletedProcess:
    """A node started with no master (``args``: its command-line arguments), SIGTERM 1 s into its start-up."""
    import select
    import signal
    import time

    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        from comm.nodelife import StopSignals

        stop = StopSignals()
        print("handlers installed", flush=True)
        print("init_node returned", stop.init_node("no_master_yet"), flush=True)
    """), *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:9/", ROS_HOME=str(tmp_path)))
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 30)  # however slow the machine is to start Python
        assert ready and proc.stdout.readline() == "handlers installed\n", proc.stderr.read()
        time.sleep(1.0)  # in init_node (or waiting for the master) by now
        assert proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


def test_a_stop_while_no_master_answers_the_start_up_ends_the_node(tmp_path):
    """rospy.init_node retries its registrations for ever without a master, holding the lock its
    own shutdown needs: the node must still end, with 0, soon after SIGTERM."""
    done = _stopped_without_a_master(tmp_path)
    assert done.returncode == 0, done.stderr
    assert "stopped during start-up: no ROS master answered at http://127.0.0.1:9/" in done.stderr


def test_private_parameters_on_the_command_line_wait_for_the_master_and_a_stop_ends_the_wait(tmp_path):
    """rospy sets _name:=value parameters on the master in init_node and raises (a traceback) when
    there is none yet; the node waits for it instead, as one without them does."""
    done = _stopped_without_a_master(tmp_path, "_speed:=2")
    assert done.returncode == 0 and "init_node returned False" in done.stdout, done.stderr
    assert ("waiting for the ROS master at http://127.0.0.1:9/ (this node's _name:=value parameters go there)"
            in done.stderr)
    assert "Traceback" not in done.stderr


def test_a_signal_is_a_keyboard_interrupt_but_waits_for_the_end_of_a_registration():
    interrupts = Interrupts()
    try:
        steps = []
        with pytest.raises(KeyboardInterrupt):
            with registering():
                os.kill(os.getpid(), signal.SIGTERM)
                steps.append("registered")   # the signal did not cut this block short
                with registering():          # nested: held until the outermost block ends
                    steps.append("nested")
                steps.append("end of block")
        assert steps == ["registered", "nested", "end of block"]
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # Python runs the handler at the next bytecode boundary
                pass
    finally:
        interrupts.restore()
    assert signal.getsignal(signal.SIGTERM) is not interrupts._on_signal


def test_without_interrupts_registering_is_a_plain_block():
    with registering():
        pass


def test_leaving_waits_for_a_shutdown_another_thread_began_to_run_its_hooks():
    """The master kicking a node out shuts rospy down from an XML-RPC thread: rospy's first hooks wake
    the node's main thread, the later ones note why (a module node's exit code 3). Leaving must not
    read that before they ran (a kicked-out module node exited 0 about one run in twenty)."""
    script = textwrap.dedent("""
        import threading, time
        import rospy, rospy.core
        from comm.nodelife import StopSignals
        stop = StopSignals()
        rospy.core.set_initialized(True)
        woke, noted = threading.Event(), []
        rospy.core.add_client_shutdown_hook(woke.set)
        rospy.core.add_preshutdown_hook(lambda reason: (time.sleep(0.3), noted.append(reason)))
        threading.Thread(target=rospy.signal_shutdown, args=("new node registered with same name",)).start()
        assert woke.wait(5)
        stop.leave(lambda: print("NOTED", noted, flush=True))
    """)
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "NOTED ['new node registered with same name']", out.stdout + out.stderr
