//! The USB tasks: the embassy-usb device, and the CDC-ACM sender and receiver between the host
//! and the application's pipes.
//!
//! VBUS is sensed on PA9 (the OTG FS core's own sensing, `vbus_detection`): a cable pull is a
//! power event (session end), usually after a bus suspend (no more SOFs for 3 ms); a re-plug is
//! power (session request), a bus reset and an enumeration. [`UsbEvents`] feeds every bus event embassy-usb gives the handler (power, bus
//! reset, suspend and resume, configuration) into `tribo_firmware::link_tx::BusState`, which says
//! whether the link is up and in which session; a bus reset ends a suspend (embassy-usb calls
//! `reset()`, never `suspended(false)`, then), so a suspend during the host's first debounce or a
//! pull and re-plug no longer leaves the sender waiting forever. When the session changes the
//! sender stops waiting on its packet, stops taking frames (the application's are refused, so they
//! wait in the run store) and, when a host is back, sends again from the first frame the host is
//! not known to have had (`tribo_firmware::link_tx::TxResend`). A packet counts as delivered only
//! once the next write (a zero-length one when idle) returned: the OTG core takes a new IN packet
//! only after the host acknowledged the previous one. A transfer that ends on a full packet is
//! closed by a zero-length packet (`link_tx::zlp_after`).

use super::*;
use tribo_firmware::link_tx::{zlp_after, BusEvent, TxResend, PACKET};

/// The device's bus events, for the sender.
pub(super) struct UsbEvents {
    pub(super) shared: &'static Shared,
}

impl UsbEvents {
    fn on(&mut self, event: BusEvent) {
        self.shared.usb_bus.lock(|s| {
            let mut state = s.get();
            state.on(event);
            s.set(state);
        });
        self.shared.usb_event.signal(());
    }
}

impl embassy_usb::Handler for UsbEvents {
    fn enabled(&mut self, enabled: bool) {
        self.on(BusEvent::Enabled(enabled));
    }
    fn reset(&mut self) {
        self.on(BusEvent::Reset);
    }
    fn suspended(&mut self, suspended: bool) {
        self.on(BusEvent::Suspended(suspended));
    }
    fn configured(&mut self, configured: bool) {
        self.on(BusEvent::Configured(configured));
    }
}

fn bus_session(shared: &Shared) -> Option<u32> {
    shared.usb_bus.lock(|s| s.get().session())
}

#[embassy_executor::task]
pub(super) async fn usb_task(mut dev: embassy_usb::UsbDevice<'static, UsbDriver>) -> ! {
    dev.run().await
}

/// What the sender holds for a resend (a frame and a packet: too big for the task's stack frame to
/// be worth copying around; one sender).
static HELD: ConstStaticCell<TxResend> = ConstStaticCell::new(TxResend::new());

/// The sender's end of one write: the write returned, or the link's session changed first.
async fn write_or_drop(
    shared: &Shared,
    session: u32,
    tx: &mut Sender<'static, UsbDriver>,
    pkt: &[u8],
) -> bool {
    loop {
        match select(tx.write_packet(pkt), shared.usb_event.wait()).await {
            Either::First(r) => return r.is_ok(),
            // An event that left the session as it was (a repeated configuration) does not
            // cancel the write; the write is restarted from scratch, which is safe because a
            // write dropped before it reached the FIFO sent nothing.
            Either::Second(()) if bus_session(shared) == Some(session) => {}
            Either::Second(()) => return false,
        }
    }
}

#[embassy_executor::task]
pub(super) async fn usb_tx_task(shared: &'static Shared, mut tx: Sender<'static, UsbDriver>) {
    let held = HELD.take();
    let mut pkt = [0u8; PACKET];
    loop {
        tx.wait_connection().await;
        shared.usb_event.reset();
        let Some(session) = bus_session(shared) else {
            // Configured but suspended (the cable is out, or the host sleeps), or not yet
            // configured: wait for the next bus event.
            shared.usb_event.wait().await;
            continue;
        };
        // What the host may lack goes first: the frame that was being sent, whole; the queue is
        // kept (its frames were never sent).
        held.reconnected();
        shared.connected.store(true, Ordering::Release);
        defmt::info!("usb: host connected");
        loop {
            if !held.pending() {
                if held.unacknowledged() && (shared.tx.is_empty() || held.room() == 0) {
                    // Nothing more to send at once: a zero-length packet, whose write returns
                    // once the host acknowledged the last packet.
                    if !write_or_drop(shared, session, &mut tx, &[]).await {
                        break;
                    }
                    held.acknowledged();
                    continue;
                }
                let room = held.room().min(PACKET);
                let n = loop {
                    match select(shared.tx.read(&mut pkt[..room]), shared.usb_event.wait()).await {
                        Either::First(n) => break Some(n),
                        Either::Second(()) if bus_session(shared) == Some(session) => {}
                        Either::Second(()) => break None,
                    }
                };
                let Some(n) = n else { break };
                held.take(&pkt[..n]);
            }
            let n = held.next_packet(&mut pkt);
            if !write_or_drop(shared, session, &mut tx, &pkt[..n]).await {
                break;
            }
            held.wrote(n);
            if zlp_after(n, PACKET, held.pending() || !shared.tx.is_empty()) {
                if !write_or_drop(shared, session, &mut tx, &[]).await {
                    break;
                }
                held.acknowledged();
            }
        }
        shared.connected.store(false, Ordering::Release);
        defmt::info!("usb: host gone (or suspended)");
    }
}

#[embassy_executor::task]
pub(super) async fn usb_rx_task(shared: &'static Shared, mut rx: Receiver<'static, UsbDriver>) {
    let mut buf = [0u8; 64];
    loop {
        rx.wait_connection().await;
        // Packets of a previous connection not yet taken by the application are stale; the empty
        // packet tells the application a new connection starts here.
        shared.rx.clear();
        shared.rx.send(heapless::Vec::new()).await;
        while let Ok(n) = rx.read_packet(&mut buf).await {
            if n == 0 {
                continue;
            }
            let bytes = heapless::Vec::from_slice(&buf[..n]).unwrap_or_default();
            shared.rx.send(bytes).await;
        }
    }
}
