//! The gRPC arrival budget (`grpc.arrival_bytes`, issue 19 item 4): the messages arriving on all
//! streams together hold at most that many bytes. Streams that keep a large message's buffers
//! fill it; the next large message is refused with RESOURCE_EXHAUSTED naming the setting and
//! counted, small messages still pass, and a stream that ends gives its share back.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use uavnav_proto::v1 as pb;
use uavnavd::RunningServer;

const MIB: usize = 1 << 20;

/// A `SensorEnvelope` for `id` with `pad` bytes in an unknown field (protobuf skips it): the
/// service acknowledges it (no payload: refused in the ack) and the stream stays open.
fn padded_envelope(id: &str, pad: usize) -> Vec<u8> {
    let mut e = vec![0x0A, id.len() as u8];
    e.extend(id.as_bytes());
    // Field 1000, length-delimited: tag (1000 << 3 | 2) = 8002 as a varint.
    e.extend([0xC2, 0x3E]);
    let mut v = pad as u64;
    while v >= 0x80 {
        e.push((v as u8) | 0x80);
        v >>= 7;
    }
    e.push(v as u8);
    e.resize(e.len() + pad, 0);
    e
}

/// An open `Ingest` stream: its sender (dropping it ends the stream) and its replies.
struct Open {
    tx: mpsc::Sender<Vec<u8>>,
    replies: tonic::Streaming<pb::IngestAck>,
}

/// Opens a stream on its own connection and sends `body`.
async fn open(server: &RunningServer, body: Vec<u8>) -> Result<Open, tonic::Status> {
    let mut grpc = raw_grpc(server).await;
    let (tx, rx) = mpsc::channel(4);
    tx.send(body).await.unwrap();
    let path = tonic::codegen::http::uri::PathAndQuery::from_static("/uavnav.v1.UavNav/Ingest");
    let resp = grpc
        .streaming(tonic::Request::new(ReceiverStream::new(rx)), path, RawCodec)
        .await?;
    Ok(Open {
        tx,
        replies: resp.into_inner(),
    })
}

/// Opens a stream, sends `body`, and waits for its first reply: the ack, or the stream's status.
async fn first_reply(server: &RunningServer, body: Vec<u8>) -> Result<Open, tonic::Status> {
    let mut o = open(server, body).await?;
    match o.replies.message().await {
        Ok(Some(_ack)) => Ok(o),
        Ok(None) => Err(tonic::Status::unknown("stream ended without a reply")),
        Err(s) => Err(s),
    }
}

fn gauge(server: &RunningServer) -> u64 {
    let text = server.metrics().encode();
    text.lines()
        .find_map(|l| l.strip_prefix("uavnav_grpc_arrival_bytes "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_share_one_arrival_budget_and_give_it_back() {
    let mut cfg = test_config();
    cfg.grpc.max_message_bytes = 8 * MIB;
    cfg.grpc.arrival_bytes = 24 * MIB as u64;
    let server = start(cfg).await;
    let big = || padded_envelope("a", 5 * MIB);

    // Two streams keep a 5 MiB message's buffers: 2 × 10 MiB of the 24.
    let a = first_reply(&server, big()).await.unwrap();
    let b = first_reply(&server, big()).await.unwrap();
    assert!(gauge(&server) >= 20 * MIB as u64, "{}", gauge(&server));

    // A third does not fit: refused before tonic reserves its buffer, naming the setting.
    let err = match first_reply(&server, big()).await {
        Ok(_) => panic!("a third 5 MiB message fitted a 24 MiB budget held at 20 MiB"),
        Err(s) => s,
    };
    assert_eq!(err.code(), tonic::Code::ResourceExhausted, "{err:?}");
    assert!(err.message().contains("grpc.arrival_bytes"), "{err:?}");
    let text = server.metrics().encode();
    assert!(
        text.contains("uavnav_grpc_arrival_refused_total 1"),
        "{text}"
    );
    assert!(
        text.contains(
            "uavnav_inputs_refused_total{transport=\"grpc\",kind=\"malformed\",reason=\"exhausted\"} 1"
        ),
        "{text}"
    );

    // Small messages still pass beside them.
    let small = first_reply(&server, padded_envelope("s", 1000))
        .await
        .unwrap();

    // A stream that ends gives its share back, and a large message fits again.
    drop(a.tx);
    drop(a.replies);
    let metrics = server.metrics().clone();
    let released = eventually(Duration::from_secs(10), || {
        let text = metrics.encode();
        text.lines()
            .find_map(|l| l.strip_prefix("uavnav_grpc_arrival_bytes "))
            .and_then(|v| v.trim().parse::<u64>().ok())
            .is_some_and(|held| held < 14 * MIB as u64)
    })
    .await;
    assert!(released, "{}", gauge(&server));
    let c = first_reply(&server, big()).await.unwrap();

    drop((b, c, small));
    let metrics = server.metrics().clone();
    let all_back = eventually(Duration::from_secs(10), || {
        metrics.encode().contains("uavnav_grpc_arrival_bytes 0\n")
    })
    .await;
    assert!(all_back, "{}", gauge(&server));
    server.shutdown().await.unwrap();
}
