//! The expert process of alfd: wires the core to the transport.
