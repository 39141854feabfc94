"""rmw_zenoh's keys, attachments, liveliness tokens and QoS as two independent implementations
compute them: zenoh-ros2-sdk (pure Python) and pamoja-ros2 (its own native engine).

    python rmw_zenoh_wire.py CASES OUT

CASES is a JSON list of `{"domain", "session", "node_id", "namespace", "node", "entity_id",
"kind", "topic", "type", "hash", "qos": {"reliable", "transient_local", "depth"}, "seq",
"stamp_ns", "gid": [16 bytes]}`; OUT gets, per case, the data key by both, the node and endpoint
tokens, the QoS text and the attachment bytes (hex) by zenoh-ros2-sdk, and the type's DDS name
and the hash's digest by pamoja.
"""

import json
import sys

from pamoja import ros2 as pamoja
from zenoh_ros2_sdk.attachment import Attachment
from zenoh_ros2_sdk.entity import EndpointEntity, EntityKind, NodeEntity
from zenoh_ros2_sdk.keyexpr import endpoint_liveliness_keyexpr, node_liveliness_keyexpr, topic_keyexpr
from zenoh_ros2_sdk.qos import QosDurability, QosHistoryKind, QosProfile, QosReliability
from zenoh_ros2_sdk.utils import ros2_to_dds_type


def main():
    cases = json.load(open(sys.argv[1]))
    out = []
    for c in cases:
        node = NodeEntity(domain_id=c["domain"], session_id=c["session"], node_id=c["node_id"],
                          node_name=c["node"], namespace=c["namespace"])
        q = c["qos"]
        qos = QosProfile(
            reliability=QosReliability.RELIABLE if q["reliable"] else QosReliability.BEST_EFFORT,
            durability=QosDurability.TRANSIENT_LOCAL if q["transient_local"] else QosDurability.VOLATILE,
            history_kind=QosHistoryKind.KEEP_LAST if q["depth"] is not None else QosHistoryKind.KEEP_ALL,
            history_depth=q["depth"] if q["depth"] is not None else 0,
        ).encode()
        dds = ros2_to_dds_type(c["type"])
        ep = EndpointEntity(node=node, entity_id=c["entity_id"],
                            kind=EntityKind.PUBLISHER if c["kind"] == "MP" else EntityKind.SUBSCRIPTION,
                            name=c["topic"], dds_type_name=dds, type_hash=c["hash"], qos=qos)
        out.append({
            "key": topic_keyexpr(c["domain"], c["topic"], dds, c["hash"]),
            "key_pamoja": pamoja.entity_key(c["domain"], c["topic"], c["type"], c["hash"]),
            "dds_pamoja": pamoja.dds_type_name(c["type"]),
            "digest_pamoja": bytes(pamoja.type_hash_digest(c["hash"]) or b"").hex(),
            "node_token": node_liveliness_keyexpr(node),
            "endpoint_token": endpoint_liveliness_keyexpr(ep),
            "qos": qos,
            "attachment": Attachment(sequence_id=c["seq"], timestamp_ns=c["stamp_ns"], gid=bytes(c["gid"])).to_bytes().hex(),
        })
    json.dump(out, open(sys.argv[2], "w"))


if __name__ == "__main__":
    main()
