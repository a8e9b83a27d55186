"""A secured Zenoh router for a lab: TLS, a user and password per process, and an access-control
list that lets each process send only what its role sends.

``make_lab(DIR, robots)`` (the ``fleet certs`` command) writes into DIR:

* ``ca.pem``/``ca.key``: a certificate authority made for this lab;
* ``router.pem``/``router.key``: the router's certificate, signed by the CA, for ``localhost``,
  ``127.0.0.1`` and the host names or addresses given;
* ``credentials.txt``: one ``user:password`` line per process (the router's dictionary);
* ``<user>.json5`` for each user: the client config of that process (the CA to trust, its user
  and password), for ``--zenoh-config``;
* ``router.json5``: the router's config (TLS, the dictionary, the access-control list).

Users are ``sim``, ``coordinator``, ``dashboard`` (the live view and ``fleet up``'s watcher,
which also answers ``fleet respawn``) and one per robot, named by its robot id. The
access-control list denies whatever it does not allow:

* every user may subscribe, query and hold liveliness tokens on ``fleet/**`` and receive what
  it subscribed to, except the robots, which may neither subscribe to nor receive ``truth``;
* only ``sim`` publishes scans, odometry, truth and ``sim/**``, and answers on ``sim/**``;
* only robot ``R`` publishes ``robot/R/{cmd_vel,pose,intent,status,map,heartbeat}``, its bids
  (``coord/bids/R``) and award acks (``coord/ack/R``), and answers for its map;
* only ``coordinator`` publishes and answers auction calls, plans, awards, placements, its state,
  events and the floor map (``coord/**``, but bids and acks);
* only ``dashboard`` answers on ``ops/**``.

``configs/zenoh/router-secure.json5`` is ``router_config(Path("lab"), DEFAULT_ROBOTS)``: the
router of a three-robot lab whose files ``fleet certs lab`` made in the router's working dir.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
import secrets
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DEFAULT_ROBOTS = 3
CERT_DAYS = 825
KEY_BITS = 3072
ROLES = ("sim", "coordinator", "dashboard")
ALL_MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)
LISTEN_MESSAGES = (
    "declare_subscriber",
    "query",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)
PUBLISH_MESSAGES = ("put", "delete")
ANSWER_MESSAGES = ("declare_queryable", "reply")
ROBOT_TOPICS = ("cmd_vel", "pose", "intent", "status", "map", "heartbeat")
SENSOR_TOPICS = ("scan", "odom", "truth")
# the coordinator's keys: single ones, and families with one key per task or robot
COORD_KEYS = ("state", "events", "map", "call")
COORD_FAMILIES = ("plan", "award", "placement")
HEADER = (
    "// A secured fleet router: TLS, a user and password per process, and an access-control\n"
    "// list (fleet/security.py says who may do what). Written by `fleet certs`.\n"
)
CLIENT_HEADER = "// The Zenoh client config of one fleet process. Written by `fleet certs`.\n"
SHIPPED_HEADER = (
    "// A secured fleet router for a lab of three robots: TLS, a user and password per process,\n"
    "// and an access-control list (fleet/security.py says who may do what and writes this\n"
    "// file: router_config(Path(\"lab\"), 3)). Make the lab's files in the router's working\n"
    "// dir with `fleet certs lab`, then run\n"
    "//   fleet router --listen tls/0.0.0.0:7447 --zenoh-config configs/zenoh/router-secure.json5\n"
    "// and each process with --connect tls/<router>:7447 --zenoh-config lab/<its user>.json5.\n"
)


class LabError(Exception):
    """A lab dir that cannot be written; the message names the path."""


@dataclass(frozen=True)
class Lab:
    """The files ``make_lab`` wrote."""

    dir: Path
    users: dict[str, str]
    router_config: Path
    client_configs: dict[str, Path]


def users(robots: int) -> list[str]:
    """Every user of a lab with ``robots`` robots: the roles, then robot-0, robot-1, ..."""
    return [*ROLES, *(f"robot-{i}" for i in range(robots))]


def _rule(
    rid: str,
    messages: Iterable[str],
    flows: Iterable[str],
    keys: Iterable[str],
    permission: str = "allow",
) -> dict[str, Any]:
    return {
        "id": rid,
        "permission": permission,
        "messages": list(messages),
        "flows": list(flows),
        "key_exprs": list(keys),
    }


def access_control(robots: int) -> dict[str, Any]:
    """The access-control list of a lab with ``robots`` robots (see the module docstring)."""
    robot_ids = [f"robot-{i}" for i in range(robots)]
    f = "fleet/*"
    rules = [
        _rule("listen", LISTEN_MESSAGES, ["ingress"], ["fleet/**"]),
        _rule("receive", ALL_MESSAGES, ["egress"], ["fleet/**"]),
        _rule(
            "deny truth",
            ["put", "declare_subscriber", "query"],
            ["ingress", "egress"],
            [f"{f}/robot/*/truth"],
            permission="deny",
        ),
        _rule(
            "sim publishes",
            PUBLISH_MESSAGES,
            ["ingress"],
            [*(f"{f}/robot/*/{t}" for t in SENSOR_TOPICS), f"{f}/sim/**"],
        ),
        _rule("sim answers", ANSWER_MESSAGES, ["ingress"], [f"{f}/sim/**"]),
        _rule(
            "coordinator publishes",
            PUBLISH_MESSAGES,
            ["ingress"],
            [f"{f}/coord/{t}" for t in COORD_KEYS] + [f"{f}/coord/{t}/**" for t in COORD_FAMILIES],
        ),
        _rule(
            "coordinator answers",
            ANSWER_MESSAGES,
            ["ingress"],
            [f"{f}/coord/plan/**", f"{f}/coord/map"],
        ),
        _rule("dashboard answers", ANSWER_MESSAGES, ["ingress"], [f"{f}/ops/**"]),
    ]
    subjects = [{"id": user, "usernames": [user]} for user in users(robots)]
    policies = [
        {"id": "everyone", "rules": ["listen", "receive"], "subjects": users(robots)},
        {"id": "robots never see truth", "rules": ["deny truth"], "subjects": robot_ids},
        {"id": "sim", "rules": ["sim publishes", "sim answers"], "subjects": ["sim"]},
        {
            "id": "coordinator",
            "rules": ["coordinator publishes", "coordinator answers"],
            "subjects": ["coordinator"],
        },
        {"id": "dashboard", "rules": ["dashboard answers"], "subjects": ["dashboard"]},
    ]
    for rid in robot_ids:
        rules.append(
            _rule(
                f"{rid} publishes",
                PUBLISH_MESSAGES,
                ["ingress"],
                [f"{f}/robot/{rid}/{t}" for t in ROBOT_TOPICS]
                + [f"{f}/coord/bids/{rid}", f"{f}/coord/ack/{rid}"],
            )
        )
        rules.append(
            _rule(f"{rid} answers", ANSWER_MESSAGES, ["ingress"], [f"{f}/robot/{rid}/map"])
        )
        policies.append(
            {"id": rid, "rules": [f"{rid} publishes", f"{rid} answers"], "subjects": [rid]}
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def router_config(lab_dir: Path, robots: int) -> dict[str, Any]:
    """The router's Zenoh config for the lab in ``lab_dir`` (paths as given: relative ones are
    read from the router's working dir)."""
    return {
        "mode": "router",
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "protocols": ["tls"],
                "tls": {
                    "root_ca_certificate": str(lab_dir / "ca.pem"),
                    "listen_certificate": str(lab_dir / "router.pem"),
                    "listen_private_key": str(lab_dir / "router.key"),
                },
            },
            "auth": {"usrpwd": {"dictionary_file": str(lab_dir / "credentials.txt")}},
        },
        "access_control": access_control(robots),
    }


def client_config(lab_dir: Path, user: str, password: str) -> dict[str, Any]:
    """The Zenoh client config of ``user``: the CA to trust, its user and password."""
    return {
        "transport": {
            "link": {"tls": {"root_ca_certificate": str(lab_dir / "ca.pem")}},
            "auth": {"usrpwd": {"user": user, "password": password}},
        },
    }


def dumps(config: dict[str, Any], header: str) -> str:
    """A config as JSON5 text (JSON, which JSON5 reads) under a comment header, with lists of
    plain values on one line."""
    return header + _json(config, "") + "\n"


def _json(value: Any, indent: str) -> str:
    inner = indent + "  "
    if isinstance(value, dict) and value:
        items = [f"{inner}{json.dumps(k)}: {_json(v, inner)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + f"\n{indent}}}"
    if isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        items = [f"{inner}{_json(v, inner)}" for v in value]
        return "[\n" + ",\n".join(items) + f"\n{indent}]"
    return json.dumps(value)


def shipped_router_config() -> str:
    """The text of configs/zenoh/router-secure.json5."""
    return dumps(router_config(Path("lab"), DEFAULT_ROBOTS), SHIPPED_HEADER)


def make_lab(lab_dir: Path, robots: int, hosts: Iterable[str] = (), days: int = CERT_DAYS) -> Lab:
    """Write a CA, the router's certificate, a password per user, their client configs and the
    router's config into ``lab_dir`` (made if missing; existing files are replaced)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    if robots < 1:
        raise ValueError(f"robots must be >= 1, got {robots}")
    try:
        lab_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise LabError(f"cannot make {lab_dir}: {e.strerror}") from None
    lab_dir = lab_dir.resolve()
    now = datetime.datetime.now(datetime.timezone.utc)
    not_after = now + datetime.timedelta(days=days)

    def key() -> rsa.RSAPrivateKey:
        return rsa.generate_private_key(public_exponent=65537, key_size=KEY_BITS)

    def name(cn: str) -> x509.Name:
        return x509.Name(
            [
                x509.NameAttribute(NameOID.ORGANIZATION_NAME, "fleet lab"),
                x509.NameAttribute(NameOID.COMMON_NAME, cn),
            ]
        )

    ca_key = key()
    ca_cert = (
        x509.CertificateBuilder()
        .subject_name(name("fleet lab CA"))
        .issuer_name(name("fleet lab CA"))
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(not_after)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), False)
        .sign(ca_key, hashes.SHA256())
    )
    names: list[x509.GeneralName] = [x509.DNSName("localhost")]
    addresses = {"127.0.0.1"}
    for host in hosts:
        try:
            addresses.add(str(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    names += [x509.IPAddress(ipaddress.ip_address(a)) for a in sorted(addresses)]
    router_key = key()
    router_cert = (
        x509.CertificateBuilder()
        .subject_name(name("fleet router"))
        .issuer_name(ca_cert.subject)
        .public_key(router_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(not_after)
        .add_extension(x509.SubjectAlternativeName(names), critical=False)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), False
        )
        .sign(ca_key, hashes.SHA256())
    )

    def pem_key(k: rsa.RSAPrivateKey) -> bytes:
        return k.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )

    passwords = {user: secrets.token_urlsafe(18) for user in users(robots)}
    _write(lab_dir / "ca.pem", ca_cert.public_bytes(serialization.Encoding.PEM))
    _write(lab_dir / "ca.key", pem_key(ca_key), secret=True)
    _write(lab_dir / "router.pem", router_cert.public_bytes(serialization.Encoding.PEM))
    _write(lab_dir / "router.key", pem_key(router_key), secret=True)
    dictionary = "".join(f"{u}:{p}\n" for u, p in passwords.items())
    _write(lab_dir / "credentials.txt", dictionary.encode(), secret=True)
    clients = {}
    for user, password in passwords.items():
        clients[user] = lab_dir / f"{user}.json5"
        text = dumps(client_config(lab_dir, user, password), CLIENT_HEADER)
        _write(clients[user], text.encode(), secret=True)
    router = lab_dir / "router.json5"
    _write(router, dumps(router_config(lab_dir, robots), HEADER).encode())
    return Lab(lab_dir, passwords, router, clients)


def _write(path: Path, data: bytes, secret: bool = False) -> None:
    """Write ``path`` atomically, readable by its owner only when ``secret``."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if secret else 0o644)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise LabError(f"cannot write {path}: {e.strerror}") from None
