"""Fit every photo of a folder on a Dask cluster and write one JSON line per photo.

    python batch_fit.py face.gpmm photos/                      # a LocalCluster of 2 workers here
    python batch_fit.py face.gpmm photos/ --scheduler tcp://scheduler:8786   # a real cluster

Each photo NAME.jpg needs NAME.pts (68 iBUG landmarks) beside it; each line names its photo
("name": NAME.jpg, "path"). Every worker loads the model
once; each fit is the deterministic `gpmm fit` (same settings and seed as given here), so the
results equal fitting the photos one after another. On a real cluster the model file and the
folder must be on a file system every worker sees (or pass --scatter to ship the model itself).
"""

import argparse
import json
import sys

from distributed import Client, LocalCluster

import gpmm
import gpmm.batch


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("folder")
    ap.add_argument("--scheduler", help="address of a running Dask scheduler (default: a LocalCluster)")
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster workers (default 2)")
    ap.add_argument("--scatter", action="store_true", help="send the model to the workers instead of a path")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--landmark-steps", type=int)
    ap.add_argument("--image-steps", type=int)
    a = ap.parse_args()
    settings = {"seed": a.seed}
    if a.landmark_steps is not None:
        settings["landmark_steps"] = a.landmark_steps
    if a.image_steps is not None:
        settings["image_steps"] = a.image_steps
    model = gpmm.load(a.model) if a.scatter else a.model
    if a.scheduler:
        client, cluster = Client(a.scheduler), None
    else:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, dashboard_address=None)
        client = Client(cluster)
    try:
        for r in gpmm.batch.fit_folder(model, a.folder, client=client, **settings):
            print(json.dumps(gpmm.jsonable(r)), flush=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
