"""Foxglove's rules for an MCAP channel's JSON schema, as a check the tests can run."""

from __future__ import annotations

SCALARS = {"boolean", "number", "integer"}


def foxglove_parses(schema: dict, name: str) -> None:
    """Raise ValueError where Foxglove's ``parseJsonSchema`` (@foxglove/mcap-support,
    which Foxglove and Lichtblick run on a ``jsonschema`` channel) throws: a schema that
    is not ``"type": "object"`` (a ``$ref`` at its root), a field without exactly one
    type (an ``anyOf``, a ``"null"``, an enumeration without its type), an object without
    ``properties`` (a map: the reader iterates them), an array of such items (its
    ``addFieldsRecursive``, read in foxglove/studio's ``parseJsonSchema.ts``)."""
    if schema.get("type") != "object":
        raise ValueError(f'{name}: expected "type": "object", got {schema.get("type")!r}')
    if not isinstance(schema.get("properties"), dict):   # Object.entries(undefined) throws
        raise ValueError(f"{name}: an object without properties")
    for field, sub in schema["properties"].items():
        where, t = f"{name}.{field}", sub.get("type")
        if t in SCALARS or (t == "string" and sub.get("contentEncoding") in (None, "base64")):
            continue
        if t == "object":
            foxglove_parses(sub, where)
        elif t == "array":
            item = sub.get("items") or {}
            if item.get("type") == "object":
                foxglove_parses(item, where)
            elif not (item.get("type") in SCALARS or
                      (item.get("type") == "string" and "contentEncoding" not in item)):
                raise ValueError(f"{where}: unsupported array item type {item.get('type')!r}")
        else:
            raise ValueError(f"{where}: unsupported field type {t!r}")
