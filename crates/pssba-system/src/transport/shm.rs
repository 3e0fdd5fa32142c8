//! Small helpers shared by the stages: publishing a header + slice, waiting for consumers,
//! termination checks.

use crate::Error;
use crate::error::{Context, bail};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use iceoryx2::service::port_factory::publish_subscribe;
use pssba_msg::HasParts;
use std::fmt::Debug;
use std::time::{Duration, Instant};

/// How long a stage waits on one listener before checking for a termination request.
pub const WAKE_INTERVAL: Duration = Duration::from_millis(500);

/// Loans a slice of `payload.len()`, writes `header` and `payload` into shared memory, sends
/// and notifies the paired event.
pub fn publish_slice<P, H>(
    publisher: &Publisher<ipc::Service, [P], H>,
    notifier: &Notifier<ipc::Service>,
    header: H,
    payload: &[P],
) -> crate::Result<()>
where
    P: Debug + ZeroCopySend + Copy + 'static,
    H: Debug + Default + ZeroCopySend + 'static,
{
    let mut sample = publisher
        .loan_slice_uninit(payload.len())
        .map_err(|e| Error::Ipc(format!("loaning {} payload elements: {e:?}", payload.len())))?;
    *sample.user_header_mut() = header;
    let sample = sample.write_from_slice(payload);
    sample.send().map_err(Error::ipc("sending"))?;
    notifier.notify().map_err(Error::ipc("notifying"))?;
    Ok(())
}

/// Like [`publish_slice`], filling the payload in place from `fill(i)` (no staging copy);
/// the header is made after the fill, right before the send, so a send time stamped in it
/// measures the transport alone.
pub fn publish_from_fn<P, H>(
    publisher: &Publisher<ipc::Service, [P], H>,
    notifier: &Notifier<ipc::Service>,
    header: impl FnOnce() -> H,
    len: usize,
    fill: impl FnMut(usize) -> P,
) -> crate::Result<()>
where
    P: Debug + ZeroCopySend + 'static,
    H: Debug + Default + ZeroCopySend + 'static,
{
    let sample = publisher
        .loan_slice_uninit(len)
        .map_err(|e| Error::Ipc(format!("loaning {len} payload elements: {e:?}")))?;
    let mut sample = sample.write_from_fn(fill);
    *sample.user_header_mut() = header();
    sample.send().map_err(Error::ipc("sending"))?;
    notifier.notify().map_err(Error::ipc("notifying"))?;
    Ok(())
}

/// Publishes one message of `total_words` words, taken in order from `words`, as samples of
/// at most `sample_words` words ([`pssba_msg::parts`]): each sample is loaned, filled in place
/// from the iterator (no staging copy), stamped with `header` and its [`pssba_msg::Parts`], sent and
/// notified. The publisher waits (backpressure) while the consumer takes the earlier parts.
pub fn publish_parts<H>(
    publisher: &Publisher<ipc::Service, [f64], H>,
    notifier: &Notifier<ipc::Service>,
    header: H,
    message_id: u64,
    total_words: usize,
    sample_words: usize,
    words: impl Iterator<Item = f64>,
) -> crate::Result<()>
where
    H: Debug + Default + ZeroCopySend + HasParts + 'static,
{
    let mut words = words.fuse();
    let mut short = false;
    for (parts, range) in pssba_msg::codec::parts::split(message_id, total_words, sample_words) {
        let mut sample_header = header;
        sample_header.set_parts(parts);
        publish_from_fn(
            publisher,
            notifier,
            || sample_header,
            range.len(),
            |_| {
                words.next().unwrap_or_else(|| {
                    short = true;
                    f64::NAN
                })
            },
        )
        .with_context(|| format!("part {} of {}", parts.index + 1, parts.count))?;
    }
    if short || words.next().is_some() {
        bail!(
            Data,
            "message {message_id}: the encoder did not produce exactly {total_words} words"
        );
    }
    Ok(())
}

/// True once SIGINT or SIGTERM reached this process (iceoryx2's node handles them).
pub fn termination_requested(node: &Node<ipc::Service>) -> bool {
    node.wait(Duration::ZERO).is_err()
}

/// Start-up handshake: waits until `service` has `count` subscribers, so nothing published
/// is lost to a consumer that is still starting. Checks every 10 ms (start-up only; the data
/// path is event-driven).
pub fn wait_for_subscribers<P, H>(
    node: &Node<ipc::Service>,
    service: &publish_subscribe::PortFactory<ipc::Service, [P], H>,
    count: usize,
    what: &str,
    timeout: Duration,
) -> crate::Result<()>
where
    P: Debug + ZeroCopySend + 'static,
    H: Debug + Default + ZeroCopySend + 'static,
{
    let started = Instant::now();
    while service.dynamic_config().number_of_subscribers() < count {
        if started.elapsed() > timeout {
            bail!(
                Run,
                "{what}: only {} of {count} consumers connected after {:.0} s",
                service.dynamic_config().number_of_subscribers(),
                timeout.as_secs_f64()
            );
        }
        if node.wait(Duration::from_millis(10)).is_err() {
            bail!(Run, "{what}: interrupted while waiting for consumers");
        }
    }
    Ok(())
}

/// The ids of `service`'s subscribers now: a new id among them is a consumer that started
/// after something was sent (a restarted stage).
pub fn subscriber_ids<P, H>(
    service: &publish_subscribe::PortFactory<ipc::Service, [P], H>,
) -> Vec<u128>
where
    P: Debug + ZeroCopySend + 'static,
    H: Debug + Default + ZeroCopySend + 'static,
{
    let mut ids = Vec::new();
    service.dynamic_config().list_subscribers(|details| {
        ids.push(details.subscriber_id.value());
        CallbackProgression::Continue
    });
    ids
}

/// Creates a notifier on `event`.
pub fn notifier(event: &pssba_msg::node::EventService) -> crate::Result<Notifier<ipc::Service>> {
    event
        .notifier_builder()
        .create()
        .map_err(|e| Error::Ipc(format!("{e:?}")))
        .context("creating a notifier")
}

/// Creates a listener on `event`.
pub fn listener(
    event: &pssba_msg::node::EventService,
) -> crate::Result<iceoryx2::port::listener::Listener<ipc::Service>> {
    event
        .listener_builder()
        .create()
        .map_err(|e| Error::Ipc(format!("{e:?}")))
        .context("creating a listener")
}

/// Shutdown handshake: a publisher's shared memory goes away with its process, and a consumer
/// that has not yet mapped a (re)allocated segment would lose the samples in it. So a producer
/// stays until every consumer of `service` has disconnected (consumers drop their subscribers
/// once they have everything), or `timeout` passes. Checks every 10 ms (shutdown only).
pub fn linger_until_unsubscribed<P, H>(
    node: &Node<ipc::Service>,
    service: &publish_subscribe::PortFactory<ipc::Service, [P], H>,
    what: &str,
    timeout: Duration,
) where
    P: Debug + ZeroCopySend + 'static,
    H: Debug + ZeroCopySend + 'static,
{
    let started = Instant::now();
    while service.dynamic_config().number_of_subscribers() > 0 {
        if started.elapsed() > timeout {
            tracing::warn!(
                "{what}: {} consumers still connected after {:.0} s; leaving anyway",
                service.dynamic_config().number_of_subscribers(),
                timeout.as_secs_f64()
            );
            return;
        }
        if node.wait(Duration::from_millis(10)).is_err() {
            return;
        }
    }
}

/// [`linger_until_unsubscribed`] for a service whose last message told its consumers to stop
/// (the smooth stage's shutdown block): a consumer that subscribed after it was sent (a
/// restarted adjust stage) never got it and would never leave, so `resend` is called once for
/// each new set of subscribers. `told` are the subscriber ids the message was sent to.
pub fn linger_telling_newcomers<P, H>(
    node: &Node<ipc::Service>,
    service: &publish_subscribe::PortFactory<ipc::Service, [P], H>,
    mut told: Vec<u128>,
    what: &str,
    timeout: Duration,
    mut resend: impl FnMut() -> crate::Result<()>,
) -> crate::Result<()>
where
    P: Debug + ZeroCopySend + 'static,
    H: Debug + Default + ZeroCopySend + 'static,
{
    let started = Instant::now();
    loop {
        let now = subscriber_ids(service);
        if now.is_empty() {
            return Ok(());
        }
        if now.iter().any(|id| !told.contains(id)) {
            tracing::info!("{what}: telling a consumer that came after the end again");
            resend()?;
            told = now;
        }
        if started.elapsed() > timeout {
            tracing::warn!(
                "{what}: {} consumers still connected after {:.0} s; leaving anyway",
                told.len(),
                timeout.as_secs_f64()
            );
            return Ok(());
        }
        if node.wait(Duration::from_millis(10)).is_err() {
            return Ok(());
        }
    }
}
