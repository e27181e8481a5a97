//! The USB tasks: the embassy-usb device, and the CDC-ACM sender and receiver between the host
//! and the application's pipes.
//!
//! A cable pull with VBUS sensing off looks to the device like a bus suspend (no more SOFs), not a
//! disconnection: [`UsbEvents`] turns a suspend, and a bus reset, into "link down" for the sender,
//! which stops waiting on its packet, stops taking frames (the application's are refused, so they
//! wait in the run store) and, when a host is back, sends again from the first frame the host cannot
//! have had (`tribo_firmware::link_tx::TxResend`). A transfer that ends on a full packet is closed
//! by a zero-length packet (`link_tx::zlp_after`).

use super::*;
use tribo_firmware::link_tx::{zlp_after, TxResend, PACKET};

/// The device's bus events, for the sender: a suspend (a pulled cable, or a sleeping host) and a
/// bus reset (a new enumeration) are "link down"; a resume wakes a sender that waits for the link.
pub(super) struct UsbEvents {
    pub(super) shared: &'static Shared,
}

impl embassy_usb::Handler for UsbEvents {
    fn suspended(&mut self, suspended: bool) {
        self.shared
            .usb_suspended
            .store(suspended, Ordering::Release);
        self.shared.usb_event.signal(());
    }
    fn reset(&mut self) {
        self.shared.usb_event.signal(());
    }
}

#[embassy_executor::task]
pub(super) async fn usb_task(mut dev: embassy_usb::UsbDevice<'static, UsbDriver>) -> ! {
    dev.run().await
}

/// What the sender holds for a resend (a frame and a packet: too big for the task's stack frame to
/// be worth copying around; one sender).
static HELD: ConstStaticCell<TxResend> = ConstStaticCell::new(TxResend::new());

#[embassy_executor::task]
pub(super) async fn usb_tx_task(shared: &'static Shared, mut tx: Sender<'static, UsbDriver>) {
    let held = HELD.take();
    let mut pkt = [0u8; PACKET];
    loop {
        tx.wait_connection().await;
        shared.usb_event.reset();
        if shared.usb_suspended.load(Ordering::Acquire) {
            // Configured but suspended (the cable is out, or the host sleeps): wait for a resume
            // or a bus reset.
            shared.usb_event.wait().await;
            continue;
        }
        // What the host may lack goes first: the frame that was being sent, whole; the queue is
        // kept (its frames were never sent).
        held.reconnected();
        shared.connected.store(true, Ordering::Release);
        defmt::info!("usb: host connected");
        loop {
            if !held.pending() {
                let room = held.room().min(PACKET);
                let n =
                    match select(shared.tx.read(&mut pkt[..room]), shared.usb_event.wait()).await {
                        Either::First(n) => n,
                        Either::Second(()) => break,
                    };
                held.take(&pkt[..n]);
            }
            let n = held.next_packet(&mut pkt);
            match select(tx.write_packet(&pkt[..n]), shared.usb_event.wait()).await {
                Either::First(Ok(())) => held.delivered(n),
                _ => break,
            }
            if zlp_after(n, PACKET, held.pending() || !shared.tx.is_empty()) {
                match select(tx.write_packet(&[]), shared.usb_event.wait()).await {
                    Either::First(Ok(())) => {}
                    _ => break,
                }
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
