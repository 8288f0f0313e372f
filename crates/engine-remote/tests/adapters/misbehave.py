"""An engine process that misbehaves on purpose, for the protocol's
failure tests. Standard library only, no SDK: it speaks the protocol by
hand, correctly until the request named by its first argument, where it
does what its second argument says:

    crash    writes a last message to standard error and exits with 3
    hang     never answers
    garbage  answers a line that is not JSON
    nan      answers a reading with a NaN joint angle
    wrong    answers a reading one joint short
    silent   closes its output and keeps running
    refuse   answers an `error` reply of kind `load`

It simulates nothing: every joint stays at 0, objects where the scene
puts them. With MISBEHAVE_STARTS=FILE in its environment it appends its
process id to FILE as it starts (the tests count the processes).
"""
import json
import os
import struct
import sys
import time

when, what = sys.argv[1], sys.argv[2]
if os.environ.get("MISBEHAVE_STARTS"):
    with open(os.environ["MISBEHAVE_STARTS"], "a") as f:
        f.write("%d\n" % os.getpid())


def bits(values):
    return struct.pack("<%dd" % len(values), *values).hex()


def reply(obj):
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


joints = 0
poses = []
t = 0.0
for line in sys.stdin:
    request = json.loads(line)
    op = request["op"]
    if op == "load":
        model = request["model"]
        joints = len(model["actuators"])
        # Objects stay at their scene poses, links at a point above.
        poses = []
        for track in model["tracked"]:
            if "object" in track:
                poses += model["objects"][track["object"]]["pose"]
            else:
                poses += [0, 0, 1, 1, 0, 0, 0]
    if op == "step":
        t += request["n"] * 0.001
    q = [0.0] * joints
    if op == when:
        if what == "crash":
            sys.stderr.write("misbehave: simulated crash in %s\n" % op)
            sys.stderr.flush()
            sys.exit(3)
        if what == "hang":
            time.sleep(3600)
        if what == "garbage":
            sys.stdout.write("Segmentation fault (core dumped)\n")
            sys.stdout.flush()
            continue
        if what == "nan":
            q[0] = float("nan")
        if what == "wrong":
            q = q[:-1]
        if what == "silent":
            os.close(1)
            time.sleep(3600)
        if what == "refuse":
            reply({"error": {"kind": "load", "message": "misbehave refuses to load"}})
            continue
    if op == "hello":
        reply({"ok": {"protocol": 1, "engine": "misbehave", "version": "misbehave 1.0",
                      "default_timestep_s": 0.001,
                      "settings": [{"key": "timestep_s", "help": "fixed at 0.001"}],
                      "params": [],
                      "commands": [{"kind": k, "mechanism": "none"}
                                   for k in ("velocity", "position", "effort")]}})
    elif op == "check_settings":
        reply({"ok": {"timestep_s": bits([0.001])}})
    else:
        reading = {"t": bits([t]), "q": bits(q), "qd": bits([0.0] * joints),
                   "poses": bits(poses)}
        reply({"ok": {"state": reading, "stability_issues": []}})
