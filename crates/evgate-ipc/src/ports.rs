//! Publishers and subscribers of the pipeline streams, each paired with the event service of the
//! same name that wakes readers up.

use std::fmt::Debug;
use std::mem::MaybeUninit;
use std::time::{Duration, Instant};

use iceoryx2::port::backpressure_strategy::BackpressureStrategy;
use iceoryx2::port::listener::{Listener, ListenerCreateError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError, NotifierNotifyError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::{ConnectionFailure, UpdateConnections};
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::port::{LoanError, SendError};
use iceoryx2::prelude::{AllocationStrategy, IceoryxSend, Node, ServiceName, ZeroCopySend};
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    Builder, PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use iceoryx2::service::port_factory::PortFactory as _;

use crate::names::{NameError, PipelineNames, Stream};
use crate::qos::{Overflow, Qos, ServiceLimits};
use crate::slice_writer::SliceWriter;
use crate::stale_service::{remove_orphaned_static_config, StaleServiceError};
use crate::Service;

/// Why a port (a publisher, subscriber, notifier or listener) could not be opened; every
/// variant names the service and keeps iceoryx2's error.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    Name(#[from] NameError),
    #[error(transparent)]
    StaleService(#[from] StaleServiceError),
    #[error("qos field buffer-size = {value} is out of range: accepted 1..={max}")]
    BufferSize { value: usize, max: usize },
    #[error("cannot open or create publish-subscribe service {service:?}: {source}")]
    PublishSubscribe {
        service: String,
        source: PublishSubscribeOpenOrCreateError,
    },
    #[error("cannot open or create event service {service:?}: {source}")]
    Event {
        service: String,
        source: EventOpenOrCreateError,
    },
    #[error("cannot create a publisher on service {service:?}: {source}")]
    Publisher {
        service: String,
        source: PublisherCreateError,
    },
    #[error("cannot create a subscriber on service {service:?}: {source}")]
    Subscriber {
        service: String,
        source: SubscriberCreateError,
    },
    #[error("cannot create a notifier on service {service:?}: {source}")]
    Notifier {
        service: String,
        source: NotifierCreateError,
    },
    #[error("cannot create a listener on service {service:?}: {source}")]
    Listener {
        service: String,
        source: ListenerCreateError,
    },
}

/// Why a sample could not be published.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    #[error("cannot loan a slice of {len} elements on service {service:?}: {source}")]
    Loan {
        service: String,
        len: usize,
        source: LoanError,
    },
    #[error("cannot send on service {service:?}: {source}")]
    Send { service: String, source: SendError },
    #[error("cannot notify the listeners of service {service:?}: {source}")]
    Notify {
        service: String,
        source: NotifierNotifyError,
    },
    #[error("cannot connect new subscribers of service {service:?}: {source}")]
    Connections {
        service: String,
        source: ConnectionFailure,
    },
}

/// Why a sample could not be received.
#[derive(Debug, thiserror::Error)]
#[error("cannot receive on service {service:?}: {source}")]
pub struct ReceiveError {
    service: String,
    source: iceoryx2::port::ReceiveError,
}

/// How one publication went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Delivery {
    /// Subscribers the sample reached.
    pub recipients: usize,
    /// Subscribers connected when the sample was sent that did not get it (full buffer under
    /// the overflow policy). A subscriber connecting or leaving during the send may make this
    /// one off.
    pub undelivered: usize,
}

/// How a [`SlicePublisher::publish_written`] went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WrittenDelivery {
    pub delivery: Delivery,
    /// Items the fill wrote; the slots after them were zeroed.
    pub written: usize,
    /// Items the fill offered beyond the slice's length, not published.
    pub overflowed: usize,
}

/// Streams readers want the newest sample of (forecasts, stats): the publisher overwrites the
/// oldest sample of a full subscriber and a late subscriber receives the latest sample.
fn wants_latest(stream: Stream) -> bool {
    matches!(stream, Stream::Forecast | Stream::Stats)
}

fn name_of(service: &ServiceName) -> String {
    service.as_str().to_owned()
}

impl OpenError {
    fn publisher(service: &ServiceName) -> impl FnOnce(PublisherCreateError) -> Self + '_ {
        move |source| Self::Publisher {
            service: name_of(service),
            source,
        }
    }

    fn subscriber(service: &ServiceName) -> impl FnOnce(SubscriberCreateError) -> Self + '_ {
        move |source| Self::Subscriber {
            service: name_of(service),
            source,
        }
    }
}

impl PublishError {
    fn send(service: &ServiceName) -> impl FnOnce(SendError) -> Self + '_ {
        move |source| Self::Send {
            service: name_of(service),
            source,
        }
    }
}

/// Opens or creates a service with `open_or_create`; when that finds the service stuck in
/// creation, removes what a dead creator left (its dead node, then a static config no live node
/// is creating) and tries once more.
fn open_or_recover<F, E>(
    node: &Node<Service>,
    name: &ServiceName,
    pattern: MessagingPattern,
    hangs_in_creation: impl Fn(&E) -> bool,
    open_or_create: impl Fn() -> Result<F, E>,
    failed: impl Fn(String, E) -> OpenError,
) -> Result<F, OpenError> {
    match open_or_create() {
        Err(error) if hangs_in_creation(&error) => {
            // A dead creator that finished its static config but not the rest is removed by
            // dead-node cleanup, unless another process was cleaning that node when ours started.
            let cleaned_dead_nodes = node.try_cleanup_dead_nodes().cleanups > 0;
            let removed_static_config = remove_orphaned_static_config(node, name, pattern)?;
            if !cleaned_dead_nodes && !removed_static_config {
                return Err(failed(name_of(name), error));
            }
            open_or_create()
        }
        outcome => outcome,
    }
    .map_err(|error| failed(name_of(name), error))
}

fn open_wakeup_service(
    node: &Node<Service>,
    name: &ServiceName,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Service>, OpenError> {
    open_or_recover(
        node,
        name,
        MessagingPattern::Event,
        |error| {
            matches!(
                error,
                EventOpenOrCreateError::EventOpenError(EventOpenError::HangsInCreation)
            )
        },
        || {
            node.service_builder(name)
                .event()
                .max_nodes(ServiceLimits::MAX_NODES)
                .open_or_create()
        },
        |service, source| OpenError::Event { service, source },
    )
}

/// `open_or_recover` for a publish-subscribe service.
fn open_or_recover_publish_subscribe<F>(
    node: &Node<Service>,
    name: &ServiceName,
    open_or_create: impl Fn() -> Result<F, PublishSubscribeOpenOrCreateError>,
) -> Result<F, OpenError> {
    open_or_recover(
        node,
        name,
        MessagingPattern::PublishSubscribe,
        |error| {
            matches!(
                error,
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::HangsInCreation
                )
            )
        },
        open_or_create,
        |service, source| OpenError::PublishSubscribe { service, source },
    )
}

fn open_notifier(node: &Node<Service>, name: &ServiceName) -> Result<Notifier<Service>, OpenError> {
    open_wakeup_service(node, name)?
        .notifier_builder()
        .create()
        .map_err(|source| OpenError::Notifier {
            service: name_of(name),
            source,
        })
}

fn open_listener(node: &Node<Service>, name: &ServiceName) -> Result<Listener<Service>, OpenError> {
    open_wakeup_service(node, name)?
        .listener_builder()
        .create()
        .map_err(|source| OpenError::Listener {
            service: name_of(name),
            source,
        })
}

fn wake_readers(notifier: &Notifier<Service>, service: &ServiceName) -> Result<(), PublishError> {
    notifier
        .notify()
        .map(|_| ())
        .map_err(|source| PublishError::Notify {
            service: name_of(service),
            source,
        })
}

fn check_buffer_size(qos: &Qos) -> Result<(), OpenError> {
    if qos.buffer_size == 0 || qos.buffer_size > ServiceLimits::SUBSCRIBER_MAX_BUFFER {
        return Err(OpenError::BufferSize {
            value: qos.buffer_size,
            max: ServiceLimits::SUBSCRIBER_MAX_BUFFER,
        });
    }
    Ok(())
}

fn overflow_strategy(qos: &Qos) -> BackpressureStrategy {
    match qos.overflow {
        Overflow::Block => BackpressureStrategy::RetryUntilDelivered,
        Overflow::DropAndCount => BackpressureStrategy::DiscardData,
    }
}

fn block_with_timeout(timeout: Duration) -> impl Fn(&BackpressureInfo) -> BackpressureAction {
    move |info: &BackpressureInfo| {
        if info.elapsed_time >= timeout {
            BackpressureAction::DiscardData
        } else {
            BackpressureAction::Retry
        }
    }
}

/// Publishes slices (`[T]` with a user header `H`) on one stream and wakes its readers.
pub struct SlicePublisher<T, H>
where
    T: Debug + ZeroCopySend + bytemuck::Pod + 'static,
    H: Debug + ZeroCopySend + Copy + Default + 'static,
{
    service_name: ServiceName,
    service: PortFactory<Service, [T], H>,
    publisher: Publisher<Service, [T], H>,
    notifier: Notifier<Service>,
}

/// Applies the crate-wide limits; a `latest` service keeps the newest sample for late
/// subscribers and overwrites the oldest sample of a full subscriber.
fn with_service_limits<P, H>(
    builder: Builder<P, H, Service>,
    latest: bool,
) -> Builder<P, H, Service>
where
    P: Debug + IceoryxSend + ?Sized,
    H: Debug + ZeroCopySend,
{
    builder
        .enable_safe_overflow(latest)
        .history_size(if latest {
            ServiceLimits::LATEST_HISTORY
        } else {
            0
        })
        .subscriber_max_buffer_size(ServiceLimits::SUBSCRIBER_MAX_BUFFER)
        .subscriber_max_borrowed_samples(ServiceLimits::SUBSCRIBER_MAX_BORROWED)
        .max_publishers(ServiceLimits::MAX_PUBLISHERS)
        .max_subscribers(ServiceLimits::MAX_SUBSCRIBERS)
        .max_nodes(ServiceLimits::MAX_NODES)
}

/// Opens (or creates) the publish-subscribe service of `stream` with the crate-wide limits.
fn open_slice_service<T, H>(
    node: &Node<Service>,
    name: &ServiceName,
    stream: Stream,
) -> Result<PortFactory<Service, [T], H>, OpenError>
where
    T: Debug + ZeroCopySend + 'static,
    H: Debug + ZeroCopySend + 'static,
{
    open_or_recover_publish_subscribe(node, name, || {
        let builder = node
            .service_builder(name)
            .publish_subscribe::<[T]>()
            .user_header::<H>();
        with_service_limits(builder, wants_latest(stream)).open_or_create()
    })
}

impl<T, H> SlicePublisher<T, H>
where
    T: Debug + ZeroCopySend + bytemuck::Pod + 'static,
    H: Debug + ZeroCopySend + Copy + Default + 'static,
{
    /// Opens the publisher of `stream` in pipeline `names`.
    pub fn open(
        node: &Node<Service>,
        names: &PipelineNames,
        stream: Stream,
        qos: &Qos,
    ) -> Result<Self, OpenError> {
        let service_name = names.service(stream)?;
        let service = open_slice_service::<T, H>(node, &service_name, stream)?;
        let builder = service
            .publisher_builder()
            .initial_max_slice_len(qos.initial_max_slice_len.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .backpressure_strategy(overflow_strategy(qos));
        let builder = match qos.overflow {
            Overflow::Block => builder.set_backpressure_handler(block_with_timeout(
                Duration::from_millis(qos.block_timeout_ms),
            )),
            Overflow::DropAndCount => builder,
        };
        let publisher = builder
            .create()
            .map_err(OpenError::publisher(&service_name))?;
        let notifier = open_notifier(node, &service_name)?;
        Ok(Self {
            service_name,
            service,
            publisher,
            notifier,
        })
    }

    /// The service name, for messages.
    pub fn service_name(&self) -> &str {
        self.service_name.as_str()
    }

    /// Connects new subscribers and hands them the history (the latest forecast); sending does
    /// this too, so only an idle publisher needs to call it.
    pub fn update_connections(&self) -> Result<(), PublishError> {
        self.publisher
            .update_connections()
            .map_err(|source| PublishError::Connections {
                service: name_of(&self.service_name),
                source,
            })
    }

    /// Subscribers currently connected.
    pub fn subscriber_count(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Publishes a copy of `items` (one memcpy into shared memory).
    pub fn publish(&self, header: H, items: &[T]) -> Result<Delivery, PublishError> {
        let sample = self.loan(header, items.len())?;
        self.send(sample.write_from_slice(items))
    }

    /// Publishes a copy of `items` again until every connected subscriber got it, dead readers
    /// were cleaned up, `deadline` passed or a signal arrived: for the end-of-stream marker,
    /// which readers wait for and must not lose to a full buffer. A reader that got an earlier
    /// copy gets another; readers ignore repeated end-of-stream markers.
    pub fn publish_until_delivered(
        &self,
        node: &Node<Service>,
        header: H,
        items: &[T],
        deadline: Instant,
    ) -> Result<Delivery, PublishError> {
        loop {
            let delivery = self.publish(header, items)?;
            if delivery.undelivered == 0 {
                return Ok(delivery);
            }
            node.try_cleanup_dead_nodes();
            if Instant::now() >= deadline || crate::stop_requested(node, Duration::from_millis(10))
            {
                return Ok(delivery);
            }
        }
    }

    /// Publishes `len` elements that `fill` writes in place, front to back, through a
    /// [`SliceWriter`]; slots it leaves unwritten are zeroed.
    pub fn publish_written(
        &self,
        header: H,
        len: usize,
        fill: impl FnOnce(&mut SliceWriter<'_, T>),
    ) -> Result<WrittenDelivery, PublishError> {
        let mut sample = self.loan(header, len)?;
        let mut writer = SliceWriter::new(sample.payload_mut());
        fill(&mut writer);
        let (written, overflowed) = (writer.written(), writer.overflowed());
        writer.fill_rest(T::zeroed());
        // SAFETY: `fill_rest` initialised every slot the fill left unwritten, and the writer
        // only initialises slots, so the whole payload is initialised.
        let sample = unsafe { sample.assume_init() };
        Ok(WrittenDelivery {
            delivery: self.send(sample)?,
            written,
            overflowed,
        })
    }

    fn loan(
        &self,
        header: H,
        len: usize,
    ) -> Result<SampleMutUninit<Service, [MaybeUninit<T>], H>, PublishError> {
        let mut sample =
            self.publisher
                .loan_slice_uninit(len)
                .map_err(|source| PublishError::Loan {
                    service: name_of(&self.service_name),
                    len,
                    source,
                })?;
        *sample.user_header_mut() = header;
        Ok(sample)
    }

    /// Publishes `len` elements that `fill` writes into zero-initialised shared memory.
    pub fn publish_with(
        &self,
        header: H,
        len: usize,
        fill: impl FnOnce(&mut [T]),
    ) -> Result<Delivery, PublishError> {
        let sample = self.loan(header, len)?;
        let mut sample = sample.write_from_fn(|_| T::zeroed());
        fill(sample.payload_mut());
        self.send(sample)
    }

    fn send(
        &self,
        sample: iceoryx2::sample_mut::SampleMut<Service, [T], H>,
    ) -> Result<Delivery, PublishError> {
        let subscribers = self.subscriber_count();
        let recipients = sample
            .send()
            .map_err(PublishError::send(&self.service_name))?;
        wake_readers(&self.notifier, &self.service_name)?;
        Ok(Delivery {
            recipients,
            undelivered: subscribers.saturating_sub(recipients),
        })
    }
}

/// Receives slices of one stream; attach [`SliceSubscriber::listener`] to a `WaitSet` to sleep
/// until a publisher sends.
pub struct SliceSubscriber<T, H>
where
    T: Debug + ZeroCopySend + 'static,
    H: Debug + ZeroCopySend + 'static,
{
    service_name: ServiceName,
    subscriber: Subscriber<Service, [T], H>,
    listener: Listener<Service>,
}

impl<T, H> SliceSubscriber<T, H>
where
    T: Debug + ZeroCopySend + 'static,
    H: Debug + ZeroCopySend + 'static,
{
    /// Opens the subscriber of `stream` in pipeline `names`; `qos.buffer_size` samples can wait.
    pub fn open(
        node: &Node<Service>,
        names: &PipelineNames,
        stream: Stream,
        qos: &Qos,
    ) -> Result<Self, OpenError> {
        check_buffer_size(qos)?;
        let service_name = names.service(stream)?;
        let service = open_slice_service::<T, H>(node, &service_name, stream)?;
        let builder = service.subscriber_builder().buffer_size(qos.buffer_size);
        let builder = if wants_latest(stream) {
            builder.history_request(ServiceLimits::LATEST_HISTORY)
        } else {
            builder
        };
        // The listener must exist before the subscriber becomes visible: a publisher may send
        // and notify the moment it sees the subscriber, and a wake-up sent to no listener is lost.
        let listener = open_listener(node, &service_name)?;
        let subscriber = builder
            .create()
            .map_err(OpenError::subscriber(&service_name))?;
        Ok(Self {
            service_name,
            subscriber,
            listener,
        })
    }

    /// The service name, for messages.
    pub fn service_name(&self) -> &str {
        self.service_name.as_str()
    }

    /// The next waiting sample, if any.
    pub fn receive(&self) -> Result<Option<Sample<Service, [T], H>>, ReceiveError> {
        self.subscriber.receive().map_err(|source| ReceiveError {
            service: name_of(&self.service_name),
            source,
        })
    }

    /// The wake-up listener: attach it to a `WaitSet` with `attach_notification`, beside an
    /// interval of [`crate::MISSED_WAKEUP_POLL`] that reads the samples too.
    pub fn listener(&self) -> &Listener<Service> {
        &self.listener
    }

    /// Clears pending wake-ups; call before draining the samples so no wake-up is lost.
    pub fn clear_wakeups(&self) {
        // A failing listener only means a spurious or missed wake-up; samples are drained anyway.
        let _ = self.listener.try_wait(|_| {});
    }
}

/// Opens the publish-subscribe service of a fixed-size value stream (stats).
fn open_value_service<T>(
    node: &Node<Service>,
    name: &ServiceName,
) -> Result<PortFactory<Service, T, ()>, OpenError>
where
    T: Debug + ZeroCopySend + 'static,
{
    open_or_recover_publish_subscribe(node, name, || {
        with_service_limits(node.service_builder(name).publish_subscribe::<T>(), true)
            .open_or_create()
    })
}

/// Publishes a fixed-size value whose newest copy is all readers need (the stats).
pub struct LatestPublisher<T: Debug + ZeroCopySend + Copy + 'static> {
    service_name: ServiceName,
    publisher: Publisher<Service, T, ()>,
    notifier: Notifier<Service>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> LatestPublisher<T> {
    pub fn open(
        node: &Node<Service>,
        names: &PipelineNames,
        stream: Stream,
    ) -> Result<Self, OpenError> {
        let service_name = names.service(stream)?;
        let publisher = open_value_service::<T>(node, &service_name)?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(OpenError::publisher(&service_name))?;
        let notifier = open_notifier(node, &service_name)?;
        Ok(Self {
            service_name,
            publisher,
            notifier,
        })
    }

    pub fn publish(&self, value: T) -> Result<(), PublishError> {
        self.publisher
            .send_copy(value)
            .map_err(PublishError::send(&self.service_name))?;
        wake_readers(&self.notifier, &self.service_name)
    }
}

/// Reads the newest value of a [`LatestPublisher`] stream.
pub struct LatestSubscriber<T: Debug + ZeroCopySend + Copy + 'static> {
    service_name: ServiceName,
    subscriber: Subscriber<Service, T, ()>,
    listener: Listener<Service>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> LatestSubscriber<T> {
    pub fn open(
        node: &Node<Service>,
        names: &PipelineNames,
        stream: Stream,
    ) -> Result<Self, OpenError> {
        let service_name = names.service(stream)?;
        // Listener first, as in `SliceSubscriber::open`, so no wake-up is lost.
        let listener = open_listener(node, &service_name)?;
        let subscriber = open_value_service::<T>(node, &service_name)?
            .subscriber_builder()
            .history_request(ServiceLimits::LATEST_HISTORY)
            .create()
            .map_err(OpenError::subscriber(&service_name))?;
        Ok(Self {
            service_name,
            subscriber,
            listener,
        })
    }

    /// The newest value received since the last call, draining older ones.
    pub fn latest(&self) -> Result<Option<T>, ReceiveError> {
        let _ = self.listener.try_wait(|_| {});
        let mut latest = None;
        while let Some(sample) = self.subscriber.receive().map_err(|source| ReceiveError {
            service: name_of(&self.service_name),
            source,
        })? {
            latest = Some(*sample.payload());
        }
        Ok(latest)
    }

    /// The wake-up listener: attach it to a `WaitSet` with `attach_notification`, beside an
    /// interval of [`crate::MISSED_WAKEUP_POLL`] that reads the samples too.
    pub fn listener(&self) -> &Listener<Service> {
        &self.listener
    }
}
