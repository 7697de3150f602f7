"""Reads an MCAP file with Foxglove's own reader (the `mcap` package from PyPI) and
prints one JSON document of what it found, for tests/e2e_live_out.rs:

{"channels": {topic: {"schema": name, "schema_encoding": .., "message_encoding": ..,
  "summary_count": n, "read": n}},
 "bad_json": n,        # messages whose data is not a JSON object
 "bad_images": n,      # CompressedImage data that is not base64 of a JPEG
 "fixes": [[lat, lon, alt], ...],   # /target/fix in file order
 "qualities": {state: n},           # /target/quality by quality state
 "target_ids": {id: n},             # /targets: how often each track id is listed
 "latency_sum_error_ms": x}   # max |sum of stage latencies - end_to_end| where all known

Usage: read_mcap.py FILE
"""
import base64
import binascii
import json
import sys

from mcap.reader import make_reader


def main(path):
    out = {"channels": {}, "bad_json": 0, "bad_images": 0, "fixes": [], "qualities": {},
           "target_ids": {}, "latency_sum_error_ms": 0.0}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        counts = summary.statistics.channel_message_counts
        for cid, ch in summary.channels.items():
            schema = summary.schemas[ch.schema_id]
            out["channels"][ch.topic] = {
                "schema": schema.name,
                "schema_encoding": schema.encoding,
                "message_encoding": ch.message_encoding,
                "summary_count": counts.get(cid, 0),
                "read": 0,
            }
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            out["channels"][channel.topic]["read"] += 1
            try:
                data = json.loads(message.data)
                assert isinstance(data, dict)
            except (ValueError, AssertionError):
                out["bad_json"] += 1
                continue
            if schema.name == "foxglove.CompressedImage":
                try:
                    jpeg = base64.b64decode(data["data"], validate=True)
                    ok = data["format"] == "jpeg" and jpeg[:2] == b"\xff\xd8"
                except (KeyError, binascii.Error):
                    ok = False
                out["bad_images"] += 0 if ok else 1
            elif channel.topic == "/target/fix":
                out["fixes"].append([data["latitude"], data["longitude"], data["altitude"]])
            elif channel.topic == "/targets":
                for t in data["targets"]:
                    key = str(t["track_id"])
                    out["target_ids"][key] = out["target_ids"].get(key, 0) + 1
            elif channel.topic == "/target/quality":
                q = data["quality"]
                out["qualities"][q] = out["qualities"].get(q, 0) + 1
            elif channel.topic == "/latency":
                parts = [data[k] for k in ("acquisition_ms", "detection_ms",
                                           "matching_ms", "geolocation_ms")]
                if all(p is not None for p in parts):
                    err = abs(sum(parts) - data["end_to_end_ms"])
                    out["latency_sum_error_ms"] = max(out["latency_sum_error_ms"], err)
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
