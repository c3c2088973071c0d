"""Access control for the secure profile: who may publish, serve and read which ARROCH keys.

The router enforces Zenoh's ``access_control`` on every link it holds (services run in client mode,
so all traffic passes through it). Identities come from the TLS client certificates' common names
(``arroch deploy certs`` makes one per role). The model is *deny by default*:

1. every known role may use the ``arroch/**`` key space (rule ``member``);
2. each :class:`Guard` then denies the roles that do not own a key what they must not do there
   (explicit deny beats explicit allow in Zenoh, whatever the order);
3. a peer whose certificate names no role matches no subject, so nothing is allowed for it: it may
   connect (its certificate is valid) but can neither publish nor receive anything.

Zenoh matches a rule only when the message's key expression is *included* in the rule's: a
subscriber declared on ``arroch/**`` is not caught by a rule on ``arroch/*/robot/*/command``. So
reading is denied on the data itself (``egress`` puts to that link, whose keys are concrete), never
on subscriber declarations, and replies are checked on their own (concrete) keys.

This table is the single source of the policy: ``arroch deploy render`` writes it into the router's
config, ``arroch deploy acl`` prints it, and the deployment tests check every guard by experiment.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

# The roles a certificate common name can stand for, and what each runs.
ROLES: dict[str, str] = {
    "planner": "task and motion planner: the only source of robot commands, plans and intents",
    "restrictor": "turns feedback into constraints; acknowledges feedback",
    "sim": "simulator or robot bridge (poses, statuses, doors, clock, cameras) and the simulated human",
    "ar": "AR client and tablet bridge: overlays, camera frames, the human's feedback",
    "supervisor": "arroch up's mission monitor: reads events and statuses",
}
# Other routers (a second site router, a relay): trusted infrastructure, no guard applies to them.
INFRASTRUCTURE: tuple[str, ...] = ("router",)

ALL_MESSAGES: tuple[str, ...] = (
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
# Liveliness keys start with a verbatim ``@`` chunk, which ``**`` never matches: list them apart.
KEY_SPACE: tuple[str, ...] = ("arroch/**", "arroch/*/@liveliness/**")


@dataclass(frozen=True)
class Guard:
    """Who may do what on one key (relative to ``arroch/<namespace>/``).

    ``publishers`` may put/delete; ``servers`` may declare a queryable and reply on it (``()``:
    nobody); ``readers`` may receive its publications (``None``: every role); ``queriers`` may send
    queries to it (``None``: every role; restricted where a query carries a payload that acts).
    """

    key: str
    why: str
    publishers: tuple[str, ...]
    servers: tuple[str, ...] = ()
    readers: tuple[str, ...] | None = None
    queriers: tuple[str, ...] | None = None

    def key_expr(self) -> str:
        return f"arroch/*/{self.key}"


GUARDS: tuple[Guard, ...] = (
    Guard(
        "robot/*/command",
        "only the planner drives the robots, and only robots hear their commands",
        publishers=("planner",),
        servers=("planner",),  # the command each robot is on, for a simulator that never got it
        readers=("sim",),
        queriers=("sim",),
    ),
    Guard(
        "feedback",
        "only the human's devices (AR clients) and the simulated human give feedback",
        publishers=("ar", "sim"),
        servers=("restrictor",),
        queriers=("ar", "sim"),
    ),
    Guard("feedback/ack/*", "only the restrictor acknowledges feedback", publishers=("restrictor",)),
    Guard(
        "constraints",
        "only the restrictor states the active constraints",
        publishers=("restrictor",),
        servers=("restrictor",),
    ),
    Guard(
        "constraints/library",
        "only the restrictor serves the constraint library the feedback buttons are built from",
        publishers=("restrictor",),
        servers=("restrictor",),
    ),
    Guard("plan", "only the planner publishes and serves the team plan", publishers=("planner",), servers=("planner",)),
    Guard("intent/*", "only the planner announces robot intents", publishers=("planner",)),
    Guard("robot/*/pose", "robot poses come from the robots (or the simulator)", publishers=("sim",)),
    Guard("robot/*/status", "robot statuses come from the robots (or the simulator)", publishers=("sim",)),
    Guard("robot/*/traffic", "the traffic rules' tables come from the robots' drivers", publishers=("sim",)),
    Guard("door/*/state", "door states come from the simulator or door sensors", publishers=("sim",)),
    Guard(
        "door/*/sensor",
        "real doors' sensors reach the world through a door controller or bridge, or the study console",
        publishers=("sim", "supervisor"),
    ),
    Guard("human/state", "where the human is comes from the simulator (or her sensors)", publishers=("sim",)),
    Guard(
        "participant/*",
        "what a study participant does comes from her tablet page, or the experimenter's console",
        publishers=("ar", "supervisor"),
    ),
    Guard("study/control", "only the experimenter's console pauses or aborts a trial", publishers=("supervisor",)),
    Guard("clock", "the site clock is the simulator's", publishers=("sim",)),
    Guard("camera/*/truth", "camera ground truth exists only in simulation", publishers=("sim",)),
    Guard("camera/*/frame", "camera frames come from the simulator or a tablet bridge", publishers=("sim", "ar")),
    Guard("ar/*/overlay", "overlays come from AR clients", publishers=("ar",)),
)


def common_names(extra: Mapping[str, Sequence[str]] | None = None) -> dict[str, list[str]]:
    """Certificate common names per role: the role's own name, plus ``extra`` (e.g. ``ar: [ar-2]``)."""
    names = {role: [role] for role in (*ROLES, *INFRASTRUCTURE)}
    for role, cns in (extra or {}).items():
        if role not in names:
            raise ValueError(f"unknown role {role!r} (roles: {', '.join(names)})")
        names[role] = list(dict.fromkeys([*names[role], *cns]))
    return names


def parse_common_names(entries: Sequence[str]) -> dict[str, list[str]]:
    """``ROLE=CN[,CN]`` entries (``--cn ar=ar-2,ar-3``) as a mapping."""
    out: dict[str, list[str]] = {}
    for entry in entries:
        role, sep, cns = entry.partition("=")
        names = [cn.strip() for cn in cns.split(",") if cn.strip()]
        if not sep or not names:
            raise ValueError(f"--cn {entry!r}: expected ROLE=NAME[,NAME...]")
        out.setdefault(role.strip(), []).extend(names)
    return out


def _deny(rule_id: str, messages: Sequence[str], flow: str, key_expr: str) -> dict:
    return {"id": rule_id, "permission": "deny", "flows": [flow], "messages": list(messages), "key_exprs": [key_expr]}


def rules_with_reasons() -> list[tuple[dict, str, list[str]]]:
    """Each rule, the reason for it, and the roles it applies to."""
    roles = list(ROLES)
    out: list[tuple[dict, str, list[str]]] = [
        (
            {
                "id": "member",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": list(ALL_MESSAGES),
                "key_exprs": list(KEY_SPACE),
            },
            "every role may use the ARROCH key space; the deny rules below carve out what it may not",
            [*roles, *INFRASTRUCTURE],
        )
    ]
    for guard in GUARDS:
        key = guard.key_expr()
        aspects: list[tuple[str, tuple[str, ...], dict]] = [
            ("publish", guard.publishers, _deny(f"{guard.key} publish", ("put", "delete"), "ingress", key)),
            ("serve", guard.servers, _deny(f"{guard.key} serve", ("declare_queryable", "reply"), "ingress", key)),
        ]
        if guard.readers is not None:
            aspects.append(
                ("read", guard.readers, _deny(f"{guard.key} read", ("put", "delete", "reply"), "egress", key))
            )
        if guard.queriers is not None:
            aspects.append(("query", guard.queriers, _deny(f"{guard.key} query", ("query",), "ingress", key)))
        for aspect, allowed, rule in aspects:
            denied = [role for role in roles if role not in allowed]
            if denied:
                who = ", ".join(allowed) if allowed else "no role"
                out.append((rule, f"{guard.key}: {aspect} only by {who} ({guard.why})", denied))
    return out


def access_control(extra_cns: Mapping[str, Sequence[str]] | None = None) -> dict:
    """The ``access_control`` block of the router's Zenoh config."""
    cns = common_names(extra_cns)
    rules = rules_with_reasons()
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [rule for rule, _, _ in rules],
        "subjects": [{"id": role, "cert_common_names": names} for role, names in cns.items()],
        "policies": [{"id": rule["id"], "rules": [rule["id"]], "subjects": subjects} for rule, _, subjects in rules],
    }


def to_json5(extra_cns: Mapping[str, Sequence[str]] | None = None, indent: str = "  ") -> str:
    """The block as commented JSON5 (one entry per line, each rule with its reason)."""
    block = access_control(extra_cns)
    reasons = [reason for _, reason, _ in rules_with_reasons()]
    i1, i2 = indent, indent * 2
    lines = [
        "{",
        f"{i1}enabled: true,",
        f"{i1}// Whatever no rule allows is denied: a certificate naming no role can do nothing.",
        f'{i1}default_permission: "deny",',
        f"{i1}rules: [",
    ]
    for rule, reason in zip(block["rules"], reasons, strict=True):
        lines += [f"{i2}// {reason}", f"{i2}{json.dumps(rule)},"]
    lines += [
        f"{i1}],",
        f"{i1}// Roles, by the common name of the TLS client certificate (arroch deploy certs).",
        f"{i1}subjects: [",
    ]
    lines += [f"{i2}{json.dumps(subject)}," for subject in block["subjects"]]
    lines += [
        f"{i1}],",
        f"{i1}// Which rules bind which roles (a deny rule binds every role not allowed).",
        f"{i1}policies: [",
    ]
    lines += [f"{i2}{json.dumps(policy)}," for policy in block["policies"]]
    lines += [f"{i1}],", "}"]
    return "\n".join(lines)
