//! Real zenoh sessions on loopback: rmw_zenoh keys, attachments and
//! liveliness tokens as seen by an independent subscriber.
#![allow(clippy::unwrap_used)]

use sepmem::transport::attachment::gid_of_liveliness_key;
use sepmem::transport::liveliness::{EntityKind, Qos, Token};
use sepmem::transport::{
    free_loopback_port, KeyMode, Participant, Received, RosType, TransportConfig,
};
use std::sync::{Arc, Mutex};
use std::time::Duration;

fn pc2() -> RosType {
    RosType::new(
        "sensor_msgs/msg/PointCloud2",
        "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    )
}

/// Open a listener on an ephemeral loopback port and a second session
/// connected to it.
async fn pair(mode: KeyMode) -> (Participant, Participant) {
    let port = free_loopback_port().unwrap();
    let mut a = TransportConfig::loopback("talker", Some(port), &[]);
    a.key_mode = mode;
    a.prefix = "pfx".into();
    let a = Participant::open(&a).await.unwrap();
    let mut b = TransportConfig::loopback("listener", None, &[port]);
    b.key_mode = mode;
    b.prefix = "pfx".into();
    let b = Participant::open(&b).await.unwrap();
    (a, b)
}

async fn until<F: Fn() -> bool>(f: F, what: &str) {
    for _ in 0..400 {
        if f() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("timed out waiting for {what}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ros2_samples_carry_valid_attachments_and_tokens_parse_back() {
    let (a, b) = pair(KeyMode::Ros2).await;
    let got: Arc<Mutex<Vec<Received>>> = Arc::default();
    let g = got.clone();
    let _sub = b
        .subscribe("/robot/**", &pc2(), move |r| g.lock().unwrap().push(r))
        .await
        .unwrap();
    let publisher = a
        .publisher("/robot/seg/points", &pc2(), Qos::SENSOR_DATA)
        .await
        .unwrap();
    // Publish until the route is up and at least 3 samples arrived.
    for i in 0..400u32 {
        if got.lock().unwrap().len() >= 3 {
            break;
        }
        publisher.put(vec![0, 1, 0, 0, i as u8]).await.unwrap();
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    let got = got.lock().unwrap().clone();
    assert!(got.len() >= 3, "received {} samples", got.len());
    let mut last_seq = 0;
    for r in &got {
        assert_eq!(
            r.key,
            "0/robot/seg/points/sensor_msgs::msg::dds_::PointCloud2_/RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5"
        );
        assert_eq!(r.topic.as_deref().unwrap(), "/robot/seg/points");
        let att = r.attachment.clone().expect("no attachment").unwrap();
        assert!(att.sequence > last_seq, "sequence not increasing");
        last_seq = att.sequence;
        // GID = XXH3-128 of the publisher's MP token, computed here from the token key.
        assert_eq!(att.gid, gid_of_liveliness_key(publisher.token_key()));
        assert!(att.timestamp_ns > 1_600_000_000_000_000_000);
        assert_eq!(&r.payload[..4], &[0, 1, 0, 0]);
    }

    // The liveliness tokens of `a` as seen from `b`.
    let replies = b.session().liveliness().get("@ros2_lv/0/**").await.unwrap();
    let mut tokens = Vec::new();
    while let Ok(reply) = tokio::time::timeout(Duration::from_secs(5), replies.recv_async()).await {
        let Ok(reply) = reply else { break };
        if let Ok(sample) = reply.result() {
            tokens.push(Token::parse(sample.key_expr().as_str()).unwrap());
        }
    }
    let node = tokens
        .iter()
        .find(|t| t.kind == EntityKind::Node && t.node == "talker")
        .expect("talker node token");
    assert_eq!(node.zid, a.zid());
    let mp = tokens
        .iter()
        .find(|t| t.kind == EntityKind::Publisher && t.node == "talker")
        .expect("talker publisher token");
    let tt = mp.topic.clone().unwrap();
    assert_eq!(tt.topic, "/robot/seg/points");
    assert_eq!(tt.dds_type, "sensor_msgs::msg::dds_::PointCloud2_");
    assert_eq!(tt.qos, Qos::SENSOR_DATA);
    assert_eq!(mp.node_id, node.node_id);
    assert!(tokens
        .iter()
        .any(|t| t.kind == EntityKind::Node && t.node == "listener"));

    // Undeclaring the publisher withdraws its token.
    let key = publisher.token_key().to_string();
    publisher.undeclare().await.unwrap();
    let mut gone = false;
    for _ in 0..200 {
        let replies = b.session().liveliness().get(key.as_str()).await.unwrap();
        let mut n = 0;
        while let Ok(Ok(_)) =
            tokio::time::timeout(Duration::from_secs(2), replies.recv_async()).await
        {
            n += 1;
        }
        if n == 0 {
            gone = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    assert!(gone, "publisher token still alive after undeclare");
    a.close().await.unwrap();
    b.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plain_mode_uses_prefixed_keys_without_attachment() {
    let (a, b) = pair(KeyMode::Plain).await;
    let got: Arc<Mutex<Vec<Received>>> = Arc::default();
    let g = got.clone();
    let _sub = b
        .subscribe("/in/*", &pc2(), move |r| g.lock().unwrap().push(r))
        .await
        .unwrap();
    let publisher = a
        .publisher("/in/cloud", &pc2(), Qos::SENSOR_DATA)
        .await
        .unwrap();
    assert_eq!(publisher.token_key(), "");
    for _ in 0..400 {
        if !got.lock().unwrap().is_empty() {
            break;
        }
        publisher.put(vec![1, 2, 3]).await.unwrap();
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    until(|| !got.lock().unwrap().is_empty(), "plain sample").await;
    let r = got.lock().unwrap()[0].clone();
    assert_eq!(r.key, "pfx/in/cloud");
    assert_eq!(r.topic.unwrap(), "/in/cloud");
    assert!(r.attachment.is_none());
    assert_eq!(r.payload, vec![1, 2, 3]);
}
