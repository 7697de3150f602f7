"""Listens where dualgeo sends its live outputs and decodes them with clients nobody
in this project wrote: pymavlink for MAVLink 2, Python's XML parser for Cursor-on-Target.

Prints one line "PORTS <mavlink> <cot>" (both bound on 127.0.0.1, chosen by the OS),
then decodes every datagram until stdin closes, then prints one JSON document:
{"mavlink": [...decoded messages...], "mavlink_bad": n, "cot": [...events...],
 "cot_bad": n}. A datagram pymavlink cannot decode (bad CRC, unknown id, truncated)
or an event that is not CoT 2.0 XML is counted as bad.
"""
import json
import os
import select
import socket
import sys
import xml.etree.ElementTree as ET

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402


def plain(value):
    """JSON has no NaN: MAVLink's "unknown" becomes null."""
    if isinstance(value, float) and value != value:
        return None
    return value


def bound():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    s.bind(("127.0.0.1", 0))
    return s


def main():
    mav_sock, cot_sock = bound(), bound()
    print(f"PORTS {mav_sock.getsockname()[1]} {cot_sock.getsockname()[1]}", flush=True)
    parser = mavlink2.MAVLink(None)
    parser.robust_parsing = True
    out = {"mavlink": [], "mavlink_bad": 0, "cot": [], "cot_bad": 0}
    stdin = sys.stdin.fileno()
    open_inputs = [mav_sock, cot_sock, stdin]
    while True:
        ready, _, _ = select.select(open_inputs, [], [], 1.0)
        if stdin in ready and not os.read(stdin, 4096):
            # dualgeo has ended: read what is still queued, then report.
            open_inputs.remove(stdin)
            for s in (mav_sock, cot_sock):
                s.setblocking(False)
            drain(mav_sock, cot_sock, parser, out)
            break
        drain_ready = [s for s in ready if s is not stdin]
        for s in drain_ready:
            handle(s, s is mav_sock, parser, out)
    print(json.dumps(out), flush=True)


def drain(mav_sock, cot_sock, parser, out):
    for s, is_mav in ((mav_sock, True), (cot_sock, False)):
        while True:
            try:
                handle(s, is_mav, parser, out)
            except BlockingIOError:
                break


def handle(sock, is_mav, parser, out):
    data = sock.recv(65536)
    if is_mav:
        try:
            msgs = parser.parse_buffer(data) or []
        except mavlink2.MAVError:
            msgs = []
        if not msgs:
            out["mavlink_bad"] += 1
        for m in msgs:
            if m.get_type() == "BAD_DATA":
                out["mavlink_bad"] += 1
                continue
            d = {k: plain(v) for k, v in m.to_dict().items()}
            d["srcSystem"] = m.get_srcSystem()
            d["srcComponent"] = m.get_srcComponent()
            d["seq"] = m.get_seq()
            out["mavlink"].append(d)
    else:
        try:
            root = ET.fromstring(data)
            point = root.find("point")
            if root.tag != "event" or root.get("version") != "2.0" or point is None:
                raise ValueError("not a CoT 2.0 event")
            ev = dict(root.attrib)
            ev["point"] = {k: float(v) for k, v in point.attrib.items()}
            track = root.find("detail/track")
            if track is not None:
                ev["track"] = {k: float(v) for k, v in track.attrib.items()}
            out["cot"].append(ev)
        except (ET.ParseError, ValueError):
            out["cot_bad"] += 1


if __name__ == "__main__":
    main()
