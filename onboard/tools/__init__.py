"""Tools around the service: the demo, the shore view, the benchmarks, the validation
reports and the offline gain design. They may use everything, the simulator included
(docs/architecture.md §2); the service never imports them."""
