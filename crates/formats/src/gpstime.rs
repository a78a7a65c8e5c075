//! GPS time: the first step of every reader, which turns the file's time tags
//! (calendar dates in GPS time, UTC milliseconds, Android nanoseconds) into one scale,
//! seconds since the GPS epoch 1980-01-06 00:00:00 GPST, so files of one drive merge.
//!
//! GPS time has no leap seconds; UTC = GPST − Δt_LS (IS-GPS-200 §20.3.3.5.2.4, where
//! Δt_LS was 13 s in 2005, 17 s in 2016 and 18 s since 2017). No leap-second table is
//! kept here: each reader takes Δt_LS from its file (RINEX `LEAP SECONDS`, GnssLogger
//! `LeapSecond`, or GSDC's GPS-time column next to its UTC one) or from the caller.

/// Seconds in a GPS week.
pub const WEEK_S: f64 = 604_800.0;
/// Seconds in a day.
const DAY_S: i64 = 86_400;
/// Days from 1970-01-01 (Unix epoch) to 1980-01-06 (GPS epoch).
const GPS_EPOCH_UNIX_DAYS: i64 = 3_657;

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's
/// `days_from_civil`, exact for every year).
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(month);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// A calendar instant on the GPS time scale (or UTC, when the caller says so).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calendar {
    /// Year, four digits.
    pub year: i64,
    /// Month 1–12.
    pub month: u32,
    /// Day 1–31.
    pub day: u32,
    /// Hour 0–23.
    pub hour: u32,
    /// Minute 0–59.
    pub minute: u32,
    /// Seconds, with fraction.
    pub second: f64,
}

impl Calendar {
    /// Seconds since the GPS epoch, reading this date as GPS time.
    pub fn to_gps_seconds(&self) -> f64 {
        let days = days_from_civil(self.year, self.month, self.day) - GPS_EPOCH_UNIX_DAYS;
        let whole = days * DAY_S + i64::from(self.hour) * 3600 + i64::from(self.minute) * 60;
        whole as f64 + self.second
    }

    /// Seconds since the GPS epoch, reading this date as UTC with `leap_s` = GPST − UTC.
    pub fn utc_to_gps_seconds(&self, leap_s: f64) -> f64 {
        self.to_gps_seconds() + leap_s
    }
}

/// Expands a two-digit RINEX 2 year: 80–99 → 19xx, 00–79 → 20xx (RINEX 2.11 §6.5).
pub fn full_year(yy: i64) -> i64 {
    match yy {
        0..=79 => 2000 + yy,
        80..=99 => 1900 + yy,
        _ => yy,
    }
}

/// GPS seconds → (week, seconds of week).
pub fn week_tow(gps_s: f64) -> (i64, f64) {
    let week = (gps_s / WEEK_S).floor();
    (week as i64, gps_s - week * WEEK_S)
}

/// (week, seconds of week) → GPS seconds.
pub fn from_week_tow(week: i64, tow: f64) -> f64 {
    week as f64 * WEEK_S + tow
}

/// Unix milliseconds (UTC) → GPS seconds, with `leap_s` = GPST − UTC.
pub fn unix_ms_utc_to_gps(unix_ms: i64, leap_s: f64) -> f64 {
    let gps_ms = unix_ms - GPS_EPOCH_UNIX_DAYS * DAY_S * 1000;
    gps_ms as f64 / 1000.0 + leap_s
}

/// Brings a time difference into ±half a week, the week-crossover rule of
/// IS-GPS-200 §20.3.3.4.3 (t_k and the clock's t − t_oc): a difference of seconds of
/// week that crossed the week's start or end is off by one week.
pub fn wrap_half_week(dt: f64) -> f64 {
    if dt > WEEK_S / 2.0 {
        dt - WEEK_S
    } else if dt < -WEEK_S / 2.0 {
        dt + WEEK_S
    } else {
        dt
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_gps_epoch_is_zero_and_a_week_later_is_week_one() {
        let c = Calendar {
            year: 1980,
            month: 1,
            day: 6,
            hour: 0,
            minute: 0,
            second: 0.0,
        };
        assert_eq!(c.to_gps_seconds(), 0.0);
        let c = Calendar { day: 13, ..c };
        assert_eq!(week_tow(c.to_gps_seconds()), (1, 0.0));
    }

    #[test]
    fn rinex_2005_start_is_week_1316_saturday() {
        // 2005-04-02 was a Saturday of GPS week 1316 (the nav file's week field).
        let c = Calendar {
            year: 2005,
            month: 4,
            day: 2,
            hour: 2,
            minute: 0,
            second: 0.0,
        };
        let (w, tow) = week_tow(c.to_gps_seconds());
        assert_eq!(w, 1316);
        assert_relative_eq!(tow, 525_600.0);
    }

    #[test]
    fn gsdc_2023_utc_millis_map_to_their_gps_nanos() {
        // GSDC 2023 row: utcTimeMillis 1694113198000 with 18 leap seconds is
        // ArrivalTimeNanosSinceGpsEpoch 1.37814841600019E+18 ns.
        let t = unix_ms_utc_to_gps(1_694_113_198_000, 18.0);
        assert_relative_eq!(t, 1_378_148_416.0, epsilon = 1e-3);
    }

    #[test]
    fn week_crossover_wraps_by_one_week() {
        assert_relative_eq!(wrap_half_week(604_700.0), -100.0);
        assert_relative_eq!(wrap_half_week(-604_700.0), 100.0);
        assert_relative_eq!(wrap_half_week(3_000.0), 3_000.0);
    }

    #[test]
    fn two_digit_years_follow_rinex() {
        assert_eq!(full_year(5), 2005);
        assert_eq!(full_year(99), 1999);
    }
}
