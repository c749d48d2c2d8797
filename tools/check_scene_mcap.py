#!/usr/bin/env python3
"""Reads the MCAP `detect --mcap` wrote with Python's `mcap` reader (the reference tool) and checks
every foxglove.SceneUpdate's cubes against `detect`'s JSON for the same message.
    train detect REC.mcap --topic T --out OUT --mcap OUT/scene.mcap
    python3 tools/check_scene_mcap.py OUT REC_STEM       # pip install mcap
"""
import json
import sys

from mcap.reader import make_reader


def main():
    out, stem = sys.argv[1], sys.argv[2]
    updates = []
    with open(f"{out}/scene.mcap", "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            if channel.topic == "/pmunet/people":
                assert schema.name == "foxglove.SceneUpdate" and channel.message_encoding == "json", (schema.name, channel.message_encoding)
                updates.append(json.loads(msg.data))
    cubes = 0
    for i, u in enumerate(updates):
        want = json.load(open(f"{out}/json/{stem}/{i:06}.json"))["detections"]
        got = u["entities"][0]["cubes"]
        assert len(got) == len(want), (i, len(got), len(want))
        for c, d in zip(got, want):
            p, s = c["pose"]["position"], c["size"]
            assert (p["x"], p["y"], p["z"], s["x"], s["y"], s["z"]) == (d["x"], d["y"], d["z"], d["l"], d["w"], d["h"]), (i, c, d)
            cubes += 1
    print(f"{len(updates)} SceneUpdates, {cubes} cubes equal to detect's JSON")


if __name__ == "__main__":
    main()
