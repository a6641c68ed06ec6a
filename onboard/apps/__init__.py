"""Programs around the service: the demo, the shore view, the benchmarks, the offline gain
design, the installer and the Foxglove relay. They may use everything, the simulator
included (docs/architecture.md §2); the service never imports them."""
