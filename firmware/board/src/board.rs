//! Binding of the rig logic to the NUCLEO-H743ZI. Placeholder until the application lands: brings
//! the clocks up and blinks the status LED.
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_time::Timer;
use panic_probe as _;

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let p = embassy_stm32::init(Default::default());
    defmt::info!("tribo-board, protocol v{}", tribo_firmware::wire::PROTOCOL_VERSION);
    let mut led = Output::new(p.PB0, Level::High, Speed::Low);
    loop {
        led.toggle();
        Timer::after_millis(500).await;
    }
}
