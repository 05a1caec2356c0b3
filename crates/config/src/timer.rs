//! `[timer]`: how the servo thread is paced, and the real-time priorities.

use crate::ConfigLoadError;
use crate::source::{S, Source, span_of};
use serde::{Deserialize, Serialize};

/// How the servo thread waits for its next period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TimerMethod {
    /// The design's timerfd: one-shot, absolute, re-armed for the next period after the
    /// work (`../shared/notes/realtime-linux.md`).
    #[default]
    Timerfd,
    /// `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`.
    Nanosleep,
    /// A periodic absolute timerfd, which the kernel re-arms inside `read()` (kept to measure
    /// against).
    #[serde(rename = "timerfd-periodic")]
    TimerfdPeriodic,
}

impl std::fmt::Display for TimerMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TimerMethod::Timerfd => "timerfd",
            TimerMethod::Nanosleep => "nanosleep",
            TimerMethod::TimerfdPeriodic => "timerfd-periodic",
        })
    }
}

impl std::str::FromStr for TimerMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<TimerMethod, String> {
        match s {
            "timerfd" => Ok(TimerMethod::Timerfd),
            "nanosleep" => Ok(TimerMethod::Nanosleep),
            "timerfd-periodic" => Ok(TimerMethod::TimerfdPeriodic),
            other => Err(format!(
                "must be \"timerfd\", \"nanosleep\" or \"timerfd-periodic\", found \"{other}\""
            )),
        }
    }
}

/// Timer and real-time priorities.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimerSettings {
    /// How the servo thread waits.
    pub method: TimerMethod,
    /// SCHED_FIFO priority of the servo thread; 0 = SCHED_OTHER.
    pub servo_priority: i32,
    /// SCHED_FIFO priority of the hwserver; 0 = SCHED_OTHER.
    pub hwserver_priority: i32,
    /// Lock all memory of both processes.
    pub lock_memory: bool,
    /// Pin the servo thread to this CPU; `None`: no pinning. Our other threads and processes
    /// then keep off it, where another CPU exists.
    pub servo_cpu: Option<usize>,
    /// Pin the hwserver to this CPU; `None`: no pinning (our other threads keep off it too).
    pub hwserver_cpu: Option<usize>,
}

impl TimerSettings {
    /// The CPUs the real-time threads are pinned to (servo thread, hwserver): the others of
    /// ours keep off them where another CPU exists (`qmarc_timer::cpus::keep_off`).
    pub fn rt_cpus(&self) -> Vec<usize> {
        self.servo_cpu.into_iter().chain(self.hwserver_cpu).collect()
    }
}

impl Default for TimerSettings {
    fn default() -> TimerSettings {
        TimerSettings {
            method: TimerMethod::Timerfd,
            servo_priority: 80,
            hwserver_priority: 85,
            lock_memory: true,
            servo_cpu: None,
            hwserver_cpu: None,
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTimer {
    method: S<String>,
    servo_priority: S<i64>,
    hwserver_priority: S<i64>,
    lock_memory: S<bool>,
    servo_cpu: S<i64>,
    hwserver_cpu: S<i64>,
}

/// A CPU to pin to: −1 (the default) is none.
fn cpu(src: &Source<'_>, v: &S<i64>, field: &str) -> Result<Option<usize>, ConfigLoadError> {
    let cpu = src.int(v, field, -1, -1, 1023)?;
    Ok(usize::try_from(cpu).ok())
}

impl RawTimer {
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<TimerSettings, ConfigLoadError> {
        let d = TimerSettings::default();
        let method = src.read(&self.method, "timer.method", d.method, |v| v.parse())?;
        let servo_priority =
            src.int(&self.servo_priority, "timer.servo_priority", d.servo_priority.into(), 0, 98)?;
        let hwserver_priority = src.int(
            &self.hwserver_priority,
            "timer.hwserver_priority",
            d.hwserver_priority.into(),
            0,
            98,
        )?;
        if servo_priority > 0 && hwserver_priority > 0 && hwserver_priority < servo_priority {
            return Err(src.invalid(
                span_of(&self.hwserver_priority),
                "timer.hwserver_priority",
                format!(
                    "must be at least timer.servo_priority ({servo_priority}): the servo thread \
                     waits on the hwserver, so the hwserver must not be preempted by it"
                ),
            ));
        }
        Ok(TimerSettings {
            method,
            servo_priority: servo_priority as i32,
            hwserver_priority: hwserver_priority as i32,
            lock_memory: src
                .take(&self.lock_memory, "timer.lock_memory", d.lock_memory, |_| Ok(()))?,
            servo_cpu: cpu(src, &self.servo_cpu, "timer.servo_cpu")?,
            hwserver_cpu: cpu(src, &self.hwserver_cpu, "timer.hwserver_cpu")?,
        })
    }
}
