#!/usr/bin/env python3
"""Connection floods against a coordinator (issue 67): for each case, opens many sockets that
hold a connection without using it, asks /healthz five times on new connections while they are
held, and prints the answer, its latency, how many flood sockets the server closed, and the
coordinator's peak RSS (VmHWM) and open descriptors.

    cargo build --release -p tessera-coordinator && scripts/hostile/connections.py
    scripts/hostile/connections.py --tessera /work/before-target/release/tessera   # another build
    scripts/hostile/connections.py http://127.0.0.1:7878 --pid PID                 # a running one

Without a URL it starts a fresh coordinator per case (plain, or TLS with a self-signed
certificate for the tls-* cases) under `ulimit -n` = --nofile (soft and hard, 1024 by default),
so that the sockets outnumber its descriptors. With a URL only the cases of its scheme run, and
the peak RSS is the process's since it started. Standard library only; Linux (/proc).
"""

import argparse
import errno
import os
import resource
import selectors
import shutil
import socket
import ssl
import statistics
import subprocess
import sys
import tempfile
import threading
import time

PROBES = 5
PROBE_TIMEOUT = 10.0


def status_of(pid):
    """(VmHWM in MB, open descriptors) of process `pid`."""
    try:
        with open(f"/proc/{pid}/status") as f:
            hwm = next(int(l.split()[1]) for l in f if l.startswith("VmHWM"))
        return hwm / 1024, len(os.listdir(f"/proc/{pid}/fd"))
    except (OSError, StopIteration):
        return float("nan"), -1


def open_sockets(host, port, sources, count, wait=5.0):
    """Connects `count` sockets at once (round robin over `sources`); those connected within
    `wait` seconds (a server that stops accepting leaves the rest in a full backlog)."""
    sel, connected = selectors.DefaultSelector(), []
    for i in range(count):
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setblocking(False)
        s.bind((sources[i % len(sources)], 0))
        if s.connect_ex((host, port)) in (0, errno.EINPROGRESS):
            sel.register(s, selectors.EVENT_WRITE)
        else:
            s.close()
    deadline = time.monotonic() + wait
    while sel.get_map() and time.monotonic() < deadline:
        for key, _ in sel.select(timeout=max(0.0, deadline - time.monotonic())):
            sel.unregister(key.fileobj)
            if key.fileobj.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) == 0:
                key.fileobj.settimeout(1.0)
                connected.append(key.fileobj)
            else:
                key.fileobj.close()
    for key in list(sel.get_map().values()):
        key.fileobj.close()
    return connected


def probe(host, port, tls):
    """GET /healthz on a new connection: (answer, seconds)."""
    start = time.monotonic()
    try:
        s = socket.create_connection((host, port), timeout=PROBE_TIMEOUT)
        if tls:
            ctx = ssl.create_default_context()
            ctx.check_hostname, ctx.verify_mode = False, ssl.CERT_NONE
            s = ctx.wrap_socket(s)
        s.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        data = b""
        while chunk := s.recv(4096):
            data += chunk
        s.close()
        answer = data.split(b" ", 2)[1].decode() if data.startswith(b"HTTP/") else "no answer"
    except socket.timeout:
        answer = "timeout"
    except OSError as e:
        answer = type(e).__name__
    return answer, time.monotonic() - start


def closed_by_server(sockets):
    """How many of `sockets` the server has closed: reading what it sent (an answer, TLS
    tickets; raw bytes, past any TLS layer) ends in EOF or an error."""
    n = 0
    for s in sockets:
        try:
            s.setblocking(False)
            while socket.socket.recv(s, 65536):
                pass
            n += 1
        except BlockingIOError:
            pass
        except OSError:
            n += 1
    return n


def flood(case, host, port, count):
    """Opens the case's sockets; returns them and a function that stops any background work."""
    stop = threading.Event()
    sources = ["127.0.0.1"] if case != "silent-tcp-8-ips" else [f"127.0.0.{i}" for i in range(2, 10)]
    sockets = open_sockets(host, port, sources, count)
    # TLS handshakes one after another: those that fit in 5 s, so that the first are still
    # within the server's 10 s first-request timeout when /healthz is asked (the rest stay
    # silent); a server that does not answer must not stall the run either
    deadline = time.monotonic() + 5
    for i, s in enumerate(sockets):
        try:
            if case == "keepalive-idle":
                s.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            elif case == "tls-idle" and time.monotonic() < deadline:
                ctx = ssl.create_default_context()
                ctx.check_hostname, ctx.verify_mode = False, ssl.CERT_NONE
                sockets[i] = ctx.wrap_socket(s)
            elif case == "slowloris":
                s.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
        except OSError:
            pass

    def dribble():
        # one byte per socket and second: a request that never ends, but is never silent
        while not stop.wait(1.0):
            for s in sockets:
                try:
                    s.send(b"a")
                except OSError:
                    pass

    if case == "slowloris":
        threading.Thread(target=dribble, daemon=True).start()
    return sockets, stop.set


def run_case(case, host, port, pid, count, tls):
    sockets, stop = flood(case, host, port, count)
    time.sleep(1.0)  # let the server take in the flood before measuring under it
    results = [probe(host, port, tls) for _ in range(PROBES)]
    closed = closed_by_server(sockets)
    hwm, fds = status_of(pid)
    stop()
    for s in sockets:
        s.close()
    answers = sorted({a for a, _ in results})
    times = [t * 1000 for a, t in results if a == "200"]
    latency = f"median {statistics.median(times):.1f} ms, worst {max(times):.1f} ms" if times else "no 200"
    print(f"{case:18} {len(sockets):5} sockets: /healthz {'/'.join(answers)} x{PROBES}, {latency}; "
          f"server closed {closed}; VmHWM {hwm:.1f} MB; fds {fds}", flush=True)


def start(tessera, nofile, work, tls):
    """A coordinator on a free loopback port: (process, host, port)."""
    args = [tessera, "serve", "--listen", "127.0.0.1:0", "--data-dir", tempfile.mkdtemp(dir=work)]
    if tls:
        cert, key = os.path.join(work, "cert.pem"), os.path.join(work, "key.pem")
        if not os.path.exists(cert):
            subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                            "-nodes", "-days", "2", "-keyout", key, "-out", cert, "-subj", "/CN=localhost",
                            "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1",
                            "-addext", "basicConstraints=critical,CA:FALSE"], check=True, capture_output=True)
        args += ["--tls-cert", cert, "--tls-key", key]
    limit = lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, nofile))
    log = open(os.path.join(work, "coordinator.log"), "ab")
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=log, preexec_fn=limit)
    line = proc.stdout.readline().decode()
    port = int(line.strip().rsplit(":", 1)[1])
    return proc, "127.0.0.1", port


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("url", nargs="?", help="a running coordinator (else one is started per case)")
    parser.add_argument("--pid", type=int, help="the running coordinator's process id (for VmHWM)")
    parser.add_argument("--tessera", default="target/release/tessera", help="the binary to start")
    parser.add_argument("--nofile", type=int, default=1024, help="its descriptor limit (soft = hard)")
    parser.add_argument("--sockets", type=int, default=2000, help="sockets per flood")
    args = parser.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    plain = ["silent-tcp", "silent-tcp-8-ips", "slowloris", "keepalive-idle"]
    tls = ["tls-no-hello", "tls-idle"]
    if args.url:
        scheme, _, authority = args.url.rstrip("/").partition("://")
        host, _, port = authority.rpartition(":")
        pid = args.pid
        for case in tls if scheme == "https" else plain:
            run_case(case, host, int(port), pid, args.sockets, scheme == "https")
        return
    work = tempfile.mkdtemp(prefix="tessera-connections-")
    try:
        print(f"{args.tessera}, ulimit -n {args.nofile}, {args.sockets} sockets per flood")
        for case in plain + tls:
            proc, host, port = start(args.tessera, args.nofile, work, case in tls)
            try:
                hwm, fds = status_of(proc.pid)
                print(f"{'(baseline)':18} {'':13} VmHWM {hwm:.1f} MB; fds {fds}", flush=True)
                run_case(case, host, port, proc.pid, args.sockets, case in tls)
            finally:
                proc.kill()
                proc.wait()
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
