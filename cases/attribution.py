"""Who made and who distributes an exported dataset: the ACDD-1.3 / IOOS-1.2 attribution that no
instrument file holds.

A case knows its instrument, positions and times; it does not know the people: creator,
publisher, institution, licence, naming authority. :class:`Attribution` holds them as the user
states them, read once from a TOML file of global attribute names (``adcpdyn export ...
--attribution ORG.toml``)::

    creator_name = "A. Hydrographer"
    creator_email = "a.hydrographer@example.org"
    creator_url = "https://example.org"
    license = "CC-BY-4.0"

What the user does not state is written ``not stated`` where the attribute is free text that
ACDD recommends or IOOS requires (names, institutions, countries, licence); addresses, e-mails
and URLs are left out rather than invented, and ``creator_sector`` is IOOS's own ``unknown``.

Without ``--attribution`` the file named by the environment variable ``ADCPDYN_ATTRIBUTION`` is
read, when set (a survey office states its identity once); either way the export names the file
used by absolute path and SHA-256 (:class:`AttributionFile`).
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path


NOT_STATED = "not stated"
ENVIRONMENT = "ADCPDYN_ATTRIBUTION"  # the default attribution file, when --attribution is not given
PARTY_TYPES = ("person", "group", "institution", "position")
# IOOS-1.2 creator_sector (https://mmisw.org/ont/ioos/sector)
SECTORS = ("academic", "gov_federal", "gov_municipal", "gov_state", "industry", "nonprofit", "other", "tribal",
           "unknown")
# the NERC G04 (ISO 19115 CI_RoleCode) roles IOOS-1.2 accepts for contributor_role
CONTRIBUTOR_ROLES = ("author", "coAuthor", "collaborator", "contributor", "custodian", "distributor", "editor",
                     "funder", "mediator", "originator", "owner", "pointOfContact", "principalInvestigator",
                     "processor", "publisher", "resourceProvider", "rightsHolder", "sponsor", "stakeholder", "user")
_EMAIL = re.compile(r"^[^@\s,]+@[^@\s,]+\.[^@\s,]+$")
_URL = re.compile(r"^https?://[^\s,]+$")
_REVERSE_DNS = re.compile(r"^[A-Za-z0-9-]+(\.[A-Za-z0-9-]+)+$")


@dataclass(frozen=True)
class Attribution:
    """Global attributes naming people and terms, as the user states them (None: not stated).

    Field names are the ACDD-1.3 / IOOS-1.2 attribute names. ``contributor_*`` may list several,
    comma-separated, in the same order.
    """

    creator_name: str | None = None
    creator_type: str | None = None  # one of PARTY_TYPES
    creator_institution: str | None = None
    creator_email: str | None = None
    creator_url: str | None = None  # the institution's URL (IOOS-1.2), not a personal page
    creator_sector: str | None = None  # one of SECTORS
    creator_country: str | None = None
    creator_address: str | None = None
    creator_city: str | None = None
    creator_state: str | None = None
    creator_postalcode: str | None = None
    creator_phone: str | None = None
    publisher_name: str | None = None
    publisher_type: str | None = None
    publisher_institution: str | None = None
    publisher_email: str | None = None
    publisher_url: str | None = None
    publisher_country: str | None = None
    publisher_address: str | None = None
    publisher_city: str | None = None
    publisher_state: str | None = None
    publisher_postalcode: str | None = None
    publisher_phone: str | None = None
    contributor_name: str | None = None
    contributor_role: str | None = None  # from CONTRIBUTOR_ROLES
    contributor_email: str | None = None
    contributor_url: str | None = None
    institution: str | None = None
    project: str | None = None
    program: str | None = None
    acknowledgment: str | None = None
    license: str | None = None
    references: str | None = None
    naming_authority: str | None = None  # reverse DNS (org.example) or a URL
    infoUrl: str | None = None  # noqa: N815 (the IOOS attribute's own spelling)
    platform: str | None = None  # a platform category without blanks, from platform_vocabulary
    platform_vocabulary: str | None = None
    platform_name: str | None = None  # the vessel's name
    platform_id: str | None = None  # letters and digits only (IOOS-1.2)

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None and not (isinstance(value, str) and value.strip()):
                raise ValueError(f"{f.name}: expected a non-empty string, got {value!r}")
        for name in ("creator_email", "publisher_email"):
            _check(name, getattr(self, name), _EMAIL, "an e-mail address")
        for name in ("creator_url", "publisher_url", "infoUrl", "platform_vocabulary"):
            _check(name, getattr(self, name), _URL, "an http(s) URL")
        for name, allowed in (("creator_type", PARTY_TYPES), ("publisher_type", PARTY_TYPES),
                              ("creator_sector", SECTORS)):
            value = getattr(self, name)
            if value is not None and value not in allowed:
                raise ValueError(f"{name}: expected one of {list(allowed)}, got {value!r}")
        for role in _items(self.contributor_role):
            if role not in CONTRIBUTOR_ROLES:
                raise ValueError(f"contributor_role: expected roles from {list(CONTRIBUTOR_ROLES)}, got {role!r}")
        for item in _items(self.contributor_email):
            _check("contributor_email", item, _EMAIL, "comma-separated e-mail addresses")
        for item in _items(self.contributor_url):
            _check("contributor_url", item, _URL, "comma-separated http(s) URLs")
        if self.naming_authority is not None and not (_REVERSE_DNS.match(self.naming_authority)
                                                      or _URL.match(self.naming_authority)):
            raise ValueError(f"naming_authority: expected reverse DNS such as \"org.example\" or a URL, "
                             f"got {self.naming_authority!r}")
        if self.platform is not None and re.search(r"\s", self.platform):
            raise ValueError(f"platform: expected one word without blanks (a platform category), got {self.platform!r}")
        if self.platform_id is not None and not self.platform_id.isalnum():
            raise ValueError(f"platform_id: expected letters and digits only, got {self.platform_id!r}")
        if (self.platform is None) != (self.platform_vocabulary is None):
            raise ValueError("platform, platform_vocabulary: expected both (a category and the vocabulary it comes "
                             "from) or neither")

    def global_attributes(self) -> dict:
        """The stated attributes, and ``not stated`` / ``unknown`` for the free-text ones left out."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}
        for name in ("creator_name", "creator_institution", "creator_country", "publisher_name",
                     "publisher_institution", "publisher_country", "institution", "project", "acknowledgment",
                     "license"):
            out.setdefault(name, NOT_STATED)
        out.setdefault("creator_sector", "unknown")
        if "contributor_role" in out:
            out["contributor_role_vocabulary"] = "https://vocab.nerc.ac.uk/collection/G04/current/"
        return out


def _items(text: str | None) -> list[str]:
    return [] if text is None else [x.strip() for x in text.split(",")]


def _check(name: str, value: str | None, pattern: re.Pattern, expected: str) -> None:
    if value is not None and not pattern.match(value):
        raise ValueError(f"{name}: expected {expected}, got {value!r}")


@dataclass(frozen=True)
class AttributionFile:
    """An :class:`Attribution` read from a TOML file, and which file: the export records it."""

    attribution: Attribution
    path: str  # absolute
    sha256: str
    given_by: str  # "--attribution" or ENVIRONMENT

    def provenance_attributes(self) -> dict:
        """``attribution_file``, ``attribution_sha256`` and ``attribution_from`` (the option or the variable)."""
        given = "the environment variable " + ENVIRONMENT if self.given_by == ENVIRONMENT else "the attribution option"
        return {"attribution_file": self.path, "attribution_sha256": self.sha256, "attribution_from": given}


def read_attribution(path, option: str = "--attribution") -> Attribution:
    """An :class:`Attribution` from a TOML file of global attribute names and string values.

    Raises
    ------
    ValueError
        One line naming ``option`` (how the file was given), the file and the key: unreadable
        TOML, an unknown attribute, a value of the wrong form (an e-mail, a URL, a vocabulary term).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (FileNotFoundError, IsADirectoryError):
        raise ValueError(f"{option}: {path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{option}: {path}: expected TOML, got a parse error ({exc})") from None
    known = {f.name for f in fields(Attribution)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{option}: {path.name}: unknown attribute(s) {unknown}; expected some of {sorted(known)}")
    try:
        return Attribution(**data)
    except ValueError as exc:
        raise ValueError(f"{option}: {path.name}: {exc}") from None


def read_attribution_file(path, option: str = "--attribution") -> AttributionFile:
    """:func:`read_attribution` with the file's absolute path and SHA-256."""
    from .hashing import sha256_of

    stated = read_attribution(path, option)
    return AttributionFile(stated, str(Path(path).resolve()), sha256_of(path), option)


def as_attribution(value) -> Attribution | AttributionFile | None:
    """An :class:`Attribution` (or :class:`AttributionFile`) as given, one read from a TOML path, or without
    one the file named by ``ADCPDYN_ATTRIBUTION`` (None when the variable is unset or empty)."""
    if isinstance(value, (Attribution, AttributionFile)):
        return value
    if value is not None:
        return read_attribution_file(value)
    default = os.environ.get(ENVIRONMENT, "").strip()
    return read_attribution_file(default, ENVIRONMENT) if default else None
