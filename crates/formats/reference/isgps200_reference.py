"""Independent reference values for navguard-formats' tests (not a test dependency).

A plain transcription of IS-GPS-200 Table 20-IV (orbit), §20.3.3.3.3.1 (clock) and
Figure 20-4 (Klobuchar), math module only, reading the RINEX nav record by hand.
Run: python3 isgps200_reference.py
"""
import math

MU = 3.986005e14
OMEGA_E = 7.2921151467e-5
F = -4.442807633e-10
C = 299792458.0


def d(s):
    return float(s.replace("D", "E"))


# tests/data/gnss/rtklib/07590920.05n, PRN 3, toc 2005-04-02 00:00:00 (second record)
REC = """ 3 05  4  2  0  0  0.0 9.673088788990D-05 3.069544618480D-12 0.000000000000D+00
    8.300000000000D+01 1.968750000000D+01 5.376652456590D-09 2.471116819930D+00
    1.018866896630D-06 6.735791102980D-03 7.564201951030D-06 5.153730749130D+03
    5.184000000000D+05-1.005828380580D-07 5.354931929380D-01-6.519258022310D-08
    9.274337998890D-01 2.158750000000D+02 6.038989687590D-01-8.278916219240D-09
   -1.525063547670D-10 1.000000000000D+00 1.316000000000D+03 0.000000000000D+00
    0.000000000000D+00 0.000000000000D+00-4.190951585770D-09 5.950000000000D+02"""


def fields(rec):
    lines = rec.splitlines()
    out = [d(lines[0][22 + 19 * k: 41 + 19 * k]) for k in range(3)]
    for ln in lines[1:]:
        out += [d(ln[3 + 19 * k: 22 + 19 * k]) for k in range(4)]
    return out


(af0, af1, af2, iode, crs, dn, m0, cuc, e, cus, sqa, toe, cic, om0, cis, i0, crc, w,
 omd, idot, _l2, week, _p, _acc, _h, tgd, _iodc) = fields(REC)
toc = 518400.0


def orbit(t):
    a = sqa ** 2
    tk = t - toe
    n = math.sqrt(MU / a ** 3) + dn
    m = m0 + n * tk
    ek = m
    for _ in range(50):
        ek = m + e * math.sin(ek)
    nu = math.atan2(math.sqrt(1 - e * e) * math.sin(ek), math.cos(ek) - e)
    phi = nu + w
    u = phi + cus * math.sin(2 * phi) + cuc * math.cos(2 * phi)
    r = a * (1 - e * math.cos(ek)) + crs * math.sin(2 * phi) + crc * math.cos(2 * phi)
    i = i0 + idot * tk + cis * math.sin(2 * phi) + cic * math.cos(2 * phi)
    om = om0 + (omd - OMEGA_E) * tk - OMEGA_E * toe
    xp, yp = r * math.cos(u), r * math.sin(u)
    x = xp * math.cos(om) - yp * math.cos(i) * math.sin(om)
    y = xp * math.sin(om) + yp * math.cos(i) * math.cos(om)
    z = yp * math.sin(i)
    dtr = F * e * sqa * math.sin(ek)
    dt = t - toc
    clk = af0 + af1 * dt + af2 * dt * dt + dtr - tgd
    return (x, y, z), clk


def klobuchar(lat_deg, lon_deg, el_deg, az_deg, tow, alpha, beta):
    phi_u, lam_u, el = lat_deg / 180, lon_deg / 180, el_deg / 180
    a = math.radians(az_deg)
    psi = 0.0137 / (el + 0.11) - 0.022
    phi_i = phi_u + psi * math.cos(a)
    phi_i = max(-0.416, min(0.416, phi_i))
    lam_i = lam_u + psi * math.sin(a) / math.cos(phi_i * math.pi)
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * math.pi)
    t = 4.32e4 * lam_i + tow
    t = t % 86400.0
    f = 1 + 16 * (0.53 - el) ** 3
    amp = sum(alpha[k] * phi_m ** k for k in range(4))
    per = sum(beta[k] * phi_m ** k for k in range(4))
    amp = max(amp, 0.0)
    per = max(per, 72000.0)
    x = 2 * math.pi * (t - 50400) / per
    if abs(x) < 1.57:
        tiono = f * (5e-9 + amp * (1 - x * x / 2 + x ** 4 / 24))
    else:
        tiono = f * 5e-9
    return tiono * C


if __name__ == "__main__":
    pos, clk = orbit(toe + 1800.0)
    print("PRN3 at toe+1800 s: x=%.4f y=%.4f z=%.4f clk_m(L1)=%.6f" % (*pos, clk * C))
    print("radius %.1f" % math.sqrt(sum(p * p for p in pos)))
    print("klobuchar m = %.9f" % klobuchar(35.0, 140.0, 30.0, 120.0, 518400.0 + 3 * 3600,
          [1.1180e-08, 1.4900e-08, -5.9600e-08, -5.9600e-08],
          [8.8060e+04, 1.6380e+04, -1.9660e+05, -1.3110e+05]))
