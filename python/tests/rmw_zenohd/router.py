"""A Zenoh router configured as rmw_zenohd is: `python router.py CONFIG.json5 ENDPOINT` opens a
router session with the configuration file (listen endpoint replaced by ENDPOINT), prints
`ready`, the eclipse-zenoh version and its id, and runs until its standard input closes. Runs
under any eclipse-zenoh 1.x (the test starts it with the newest and with the oldest one
rmw_zenoh releases use)."""

import json
import sys
from importlib.metadata import version

import zenoh


def main() -> None:
    conf = zenoh.Config.from_file(sys.argv[1])
    conf.insert_json5("listen/endpoints", json.dumps([sys.argv[2]]))
    with zenoh.open(conf) as session:
        print("ready", version("eclipse-zenoh"), session.info.zid(), flush=True)
        sys.stdin.read()


if __name__ == "__main__":
    main()
