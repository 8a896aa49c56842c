//! Transport adapters: they move bytes and call the service facade ([`crate::service`]); no domain
//! logic here.
//!
//! | file | adapter |
//! |---|---|
//! | [`ack_runs`] | one acknowledgement for a run of plain acceptances on an `Ingest` stream that asks for it |
//! | [`arrivals`] | one byte budget for the gRPC messages arriving on all streams (`grpc.arrival_bytes`) |
//! | [`conn`] | every TCP listener's accept loop: connection limits, idle timeout, TLS handshakes, the file-descriptor budget |
//! | [`grpc`] | the tonic `uavnav.v1.UavNav` service |
//! | [`grpc_serve`] | the gRPC port's HTTP/2 connections, with every buffer set here (the per-stream send buffer among them) |
//! | [`http`] | `/metrics`, `/livez`, `/readyz` |
//! | [`response_queue`] | the queue of a gRPC response stream (acknowledgements, watches), bounded in bytes |
//! | [`stream_limit`] | one limit on the gRPC streams open on all connections (`grpc.max_streams`) |
//! | [`zenoh`] | the embedded Zenoh session: inputs, outputs, queryables, liveliness |
//! | [`zenoh_out`] | the Zenoh output task: poses and health put only while a remote subscriber matches their leaf |
//! | [`zenoh_stats`] | what Zenoh dropped on congested links, read from its runtime into `/metrics` |

pub mod ack_runs;
pub mod arrivals;
pub mod conn;
pub mod grpc;
pub mod grpc_serve;
pub mod http;
pub mod response_queue;
pub mod stream_limit;
pub mod zenoh;
pub mod zenoh_out;
pub mod zenoh_stats;
