"""`vtdslam fetch`: the standard benchmarks by name (TUM RGB-D, Bonn RGB-D Dynamic), downloaded, verified and
unpacked in the layout `vtdslam run` and the upload accept. A tool of the CLI: nothing on the runtime path
imports it, and nothing here touches the network at import."""
