"""The address a ROS node advertises, and whether the others can reach it (README, "Several machines").

ROS 1 nodes connect to each other directly: each registers ``http://HOST:PORT/`` with the master,
HOST being ``ROS_HOSTNAME``, else ``ROS_IP``, else the machine's name (``__hostname:=``/``__ip:=``
arguments first), and every other node (the master included) connects to that. A HOST that the
others cannot reach fails silently: rospy starts, registers, and nothing ever connects. Three
mistakes are common: a name that does not resolve (minimal images, containers); a loopback
address while other machines take part (Ubuntu maps the machine's name to 127.0.1.1, and
``ROS_IP=127.0.0.1`` is copied from single-machine instructions); an address that is not this
machine's (a copied ``ROS_IP``, a changed DHCP lease).

:func:`own_address_problem` tells this process's own (each bmtree process warns once at start,
:func:`warn_own_address`); :func:`reach` and :func:`node_address_problem` tell another node's, from
the URI it registered.
"""
from __future__ import annotations

import errno
import ipaddress
import os
import socket
import sys
import urllib.parse
import xmlrpc.client
from dataclasses import dataclass
from typing import Callable, List, Mapping, Optional, Sequence

from comm.rpc import proxy

__all__ = ["OwnAddress", "AddressProblem", "advertised", "resolve", "is_loopback", "is_own_address",
           "suggested_address", "own_address_problem", "warn_own_address", "master_is_remote", "uri_host",
           "REFUSED", "reach", "node_address_problem", "FIX"]

FIX = "set ROS_IP=<an address of this machine on the robot's network%s>"
REFUSED = "connection refused"


@dataclass(frozen=True)
class OwnAddress:
    """What this process advertises: ``host``, and where it comes from: ``variable`` is
    ``ROS_HOSTNAME``, ``ROS_IP``, ``__hostname:=`` or ``__ip:=``, or "" for the machine's name."""

    host: str
    variable: str = ""

    def said(self) -> str:
        """``ROS_IP=127.0.0.1``, or ``this machine's name 'vm'``."""
        if not self.variable:
            return "this machine's name %r" % self.host
        return "%s%s%s" % (self.variable, "" if self.variable.endswith("=") else "=", self.host)


@dataclass(frozen=True)
class AddressProblem:
    """Why the others cannot connect to this process: ``kind`` is ``unresolved``, ``loopback`` (a
    loopback address while the master's is not) or ``foreign`` (not an address of this machine);
    ``text``: the whole line, the fix included; ``where``: the address said short
    (``ROS_IP=127.0.0.1, a loopback address``)."""

    kind: str
    text: str
    where: str = ""

    def __str__(self) -> str:
        return self.text


def advertised(environ: Optional[Mapping[str, str]] = None, argv: Optional[Sequence[str]] = None,
               hostname: Callable[[], str] = socket.gethostname) -> OwnAddress:
    """The host this process's nodes put in their URIs, as rosgraph chooses it
    (``rosgraph.network.get_host_name``); an empty variable counts as unset, as there."""
    env = os.environ if environ is None else environ
    for arg in sys.argv if argv is None else argv:
        for key in ("__hostname:=", "__ip:="):
            if arg.startswith(key) and arg[len(key):]:
                return OwnAddress(arg[len(key):], key)
    for key in ("ROS_HOSTNAME", "ROS_IP"):  # ROS_HOSTNAME wins over ROS_IP
        if env.get(key):
            return OwnAddress(env[key], key)
    try:
        name = hostname()
    except OSError:
        name = ""
    if not name or name == "localhost" or name.startswith("127."):  # rosgraph takes an interface's address then
        return OwnAddress(_interface_address() or "127.0.0.1", "")
    return OwnAddress(name, "")


def _interface_address() -> str:
    try:
        import rosgraph.network

        return str(rosgraph.network.get_local_address())
    except Exception:  # no netifaces
        return ""


def _ipv6(environ: Optional[Mapping[str, str]] = None) -> bool:
    return (os.environ if environ is None else environ).get("ROS_IPV6") == "on"


def resolve(host: str, ipv6: Optional[bool] = None) -> List[str]:
    """The addresses ``host`` (a name or an address) stands for; [] when it does not resolve."""
    try:
        return [str(ipaddress.ip_address(host.strip("[]")))]
    except ValueError:
        pass
    family = socket.AF_UNSPEC if (_ipv6() if ipv6 is None else ipv6) else socket.AF_INET
    try:
        found = socket.getaddrinfo(host, None, family, socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return []
    out: List[str] = []
    for *_, sockaddr in found:
        if sockaddr[0] not in out:
            out.append(str(sockaddr[0]))
    return out


def is_loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address.split("%")[0]).is_loopback
    except ValueError:
        return False


def is_own_address(address: str) -> bool:
    """True if ``address`` is one of this machine's (loopback included): a socket can be bound to it.
    True too when that cannot be told (no false alarm)."""
    if is_loopback(address):
        return True
    try:
        family = socket.AF_INET6 if ":" in address else socket.AF_INET
        with socket.socket(family, socket.SOCK_DGRAM) as sock:
            sock.bind((address, 0))
        return True
    except OSError as exc:
        return exc.errno != errno.EADDRNOTAVAIL


def suggested_address(master_uri: str) -> str:
    """An address of this machine the others can reach: the one this machine sends from towards
    the master (no packet is sent), else its first non-loopback interface address; "" if none."""
    for address in resolve(uri_host(master_uri)):
        if is_loopback(address):
            continue
        try:
            with socket.socket(socket.AF_INET6 if ":" in address else socket.AF_INET, socket.SOCK_DGRAM) as sock:
                sock.connect((address, urllib.parse.urlsplit(master_uri).port or 11311))
                mine = str(sock.getsockname()[0])
            if not is_loopback(mine):
                return mine
        except OSError:
            continue
    try:
        import rosgraph.network

        found = [str(a) for a in rosgraph.network.get_local_addresses()]  # (not ROS_IP: that may be the wrong one)
    except Exception:  # no netifaces
        found = []
    return next((a for a in found if not is_loopback(a) and not a.startswith("fe80:")), "")


def uri_host(uri: str) -> str:
    try:
        return urllib.parse.urlsplit(uri).hostname or ""
    except ValueError:
        return ""


def master_is_remote(master_uri: str) -> bool:
    """True if the master's URI names a non-loopback address (other machines may take part);
    False for a loopback one and for one that does not resolve (nothing to tell then)."""
    found = resolve(uri_host(master_uri))
    return bool(found) and not any(is_loopback(a) for a in found)


def _master_uri() -> str:
    try:
        import rosgraph

        return str(rosgraph.get_master_uri())  # __master:= first, as rospy
    except Exception:
        return os.environ.get("ROS_MASTER_URI", "http://localhost:11311/")


def own_address_problem(master_uri: Optional[str] = None, own: Optional[OwnAddress] = None,
                        suggest: Optional[Callable[[str], str]] = None,
                        mine: Callable[[str], bool] = is_own_address) -> Optional[AddressProblem]:
    """Why nodes may be unable to connect back to this process (None when nothing is wrong)."""
    master_uri = _master_uri() if master_uri is None else master_uri
    own = advertised() if own is None else own
    found = resolve(own.host)

    def fix() -> str:
        example = (suggest or suggested_address)(master_uri)
        text = FIX % (", e.g. %s" % example if example else "")
        if own.variable == "ROS_HOSTNAME":
            text += " and unset ROS_HOSTNAME (it wins over ROS_IP)"
        return text

    if not found:
        what = "ROS_HOSTNAME=%s" % own.host if own.variable == "ROS_HOSTNAME" else own.said()
        if master_is_remote(master_uri):   # a loopback address would be no fix: name this machine's own
            example = (suggest or suggested_address)(master_uri)
            hint = "export ROS_IP=%s, this machine's address towards the master %s" % (
                example, master_uri) if example else "the master %s is on another machine" % master_uri
        else:
            hint = "export ROS_IP=127.0.0.1 when every node runs here"
        return AddressProblem("unresolved", (
            "%s does not resolve, so other nodes cannot connect back to this process: set ROS_IP to "
            "this machine's address on the ROS network (%s) or ROS_HOSTNAME to a name the other machines "
            "resolve" % (what, hint)), "%s, which does not resolve" % what)
    shown = own.said() if own.host in found else "%s (%s%s)" % (
        own.said(), ", ".join(found), "" if own.variable else "; ROS_IP is not set")
    if all(is_loopback(a) for a in found):
        if not master_is_remote(master_uri):
            return None
        return AddressProblem("loopback", (
            "%s is a loopback address while the ROS master %s is not: nodes on other machines cannot connect "
            "to this process (they would reach themselves): %s" % (shown, master_uri, fix())),
            "%s, a loopback address" % shown)
    if not any(mine(a) for a in found):
        return AddressProblem("foreign", (
            "%s is not an address of this machine, so other nodes cannot connect to this process: %s"
            % (shown, fix())), "%s, not an address of this machine" % shown)
    return None


_warned = [False]


def warn_own_address(write: Optional[Callable[[str], object]] = None) -> Optional[AddressProblem]:
    """Say :func:`own_address_problem` on stderr, once per process ("warning: ..."); the problem."""
    problem = own_address_problem()
    if problem is not None and not _warned[0]:
        _warned[0] = True
        (write or sys.stderr.write)("warning: %s\n" % problem)
    return problem


def reach(uri: str, timeout: float = 1.0) -> str:
    """"" when the node at ``uri`` answers ``getPid``; else why not: :data:`REFUSED` (nothing
    listens there: its process is gone, or it is not this machine's loopback), ``timed out``,
    ``no route to host``, ``its name does not resolve here``, ``not a ROS node``..."""
    if not uri_host(uri):
        return "not a node's URI"
    try:
        code, _, _ = proxy(uri, timeout).getPid("/bmtree")
        return "" if code == 1 else "not a ROS node"
    except ConnectionRefusedError:
        return REFUSED
    except socket.gaierror:
        return "its name does not resolve here"
    except socket.timeout:
        return "timed out"
    except (xmlrpc.client.Error, ValueError):  # answered, not as a ROS node: another process on its port
        return "not a ROS node"
    except OSError as exc:
        return (exc.strerror or str(exc)).lower()


def node_address_problem(node: str, uri: str, failure: str, master_uri: Optional[str] = None) -> str:
    """Why ``node``, which registered ``uri`` and answered here with ``failure`` (:func:`reach`),
    cannot be reached because of its address; "" when its address is fine (a refused connection
    to an address that can be right means its process is gone, which is for the caller to say).

    A loopback URI while the master's is not: the master and the other machines cannot reach it
    even if it answers here. A timeout or no route to an address not of this machine: a wrong
    ``ROS_IP`` (or that machine is off the network)."""
    master_uri = _master_uri() if master_uri is None else master_uri
    host = uri_host(uri)
    found = resolve(host)
    named = bool(host) and found != [host.strip("[]")]
    variable = "ROS_IP or ROS_HOSTNAME" if named else "ROS_IP"
    if found and all(is_loopback(a) for a in found) and master_is_remote(master_uri):
        what = "a name of a loopback address here (%s)" % ", ".join(found) if named else "a loopback address"
        if not failure:
            return ("node %s registered %s, %s, which the master and the nodes on other machines cannot reach: a "
                    "wrong %s on the machine that runs it?" % (node, uri, what, variable))
        return ("node %s registered %s, %s, which does not answer from here (%s): a wrong %s on the machine that "
                "runs it?" % (node, uri, what, failure, variable))
    if not failure or failure == REFUSED or failure == "not a ROS node":
        return ""
    if found and any(is_own_address(a) for a in found):  # this machine: the process is stuck, not misaddressed
        return ""
    return ("node %s registered %s, which does not answer from here (%s): a wrong %s on the machine that runs it "
            "(or is that machine off the network)?" % (node, uri, failure, variable))
