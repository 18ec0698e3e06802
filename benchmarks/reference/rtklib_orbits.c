/* rtklib_orbits.c: print broadcast satellite positions and clocks computed by RTKLIB.
 *
 * An independent reference for mixnav's gnss/orbits.py (see
 * benchmarks/reference/make_rtklib_orbit_pins.py, which builds and runs it).
 * Links against RTKLIB (rtklibexplorer/RTKLIB, src/), built under /tmp only.
 *
 * usage: rtklib_orbits NAVFILE... < queries
 *   each query line: "SAT WEEK TOW" (satellite id such as G05, R12, E11, C08,
 *   J01; GPS week and seconds of week).
 * output, one line per query:
 *   SAT WEEK TOW TOE_WEEK TOE_TOW CODE FRQ X Y Z DTS
 *   (record reference time in GPST; Galileo data-source word or 0; GLONASS
 *   frequency number or 0; ECEF [m]; satellite clock [s] with the
 *   relativistic term, without group delay), or "SAT WEEK TOW none".
 * Record choice: the satellite's record with the reference time nearest the
 * query (ties: the later one in the file); Galileo: I/NAV records only (data
 * source bit 9, clock for E5b/E1). The orbit and clock are RTKLIB's eph2pos /
 * geph2pos, i.e. its own implementation of the ICDs.
 */
#include <stdio.h>
#include <string.h>
#include <math.h>
#include "rtklib.h"

int main(int argc, char **argv)
{
    nav_t nav = {0};
    char line[256], id[16];
    int i, k, week, wk;
    double tow, rs[6], dts, var, best, d;

    for (k = 1; k < argc; k++) {
        if (!readrnx(argv[k], 0, "", NULL, &nav, NULL)) {
            fprintf(stderr, "cannot read %s\n", argv[k]);
            return 1;
        }
    }
    while (fgets(line, sizeof(line), stdin)) {
        if (sscanf(line, "%15s %d %lf", id, &week, &tow) != 3) continue;
        gtime_t t = gpst2time(week, tow);
        int sat = satid2no(id), sys = satsys(sat, NULL), j = -1;
        best = 1e99;
        if (sys == SYS_GLO) {
            for (i = 0; i < nav.ng; i++) {
                if (nav.geph[i].sat != sat) continue;
                d = fabs(timediff(t, nav.geph[i].toe));
                if (d <= best) { best = d; j = i; }
            }
            if (j < 0) { printf("%s %d %.3f none\n", id, week, tow); continue; }
            geph2pos(t, nav.geph + j, rs, &dts, &var);
            double toe = time2gpst(nav.geph[j].toe, &wk);
            printf("%s %d %.3f %d %.3f 0 %d %.4f %.4f %.4f %.15e\n", id, week, tow, wk, toe,
                   nav.geph[j].frq, rs[0], rs[1], rs[2], dts);
        } else {
            for (i = 0; i < nav.n; i++) {
                if (nav.eph[i].sat != sat) continue;
                if (sys == SYS_GAL && !(nav.eph[i].code & (1 << 9))) continue;
                d = fabs(timediff(t, nav.eph[i].toe));
                if (d <= best) { best = d; j = i; }
            }
            if (j < 0) { printf("%s %d %.3f none\n", id, week, tow); continue; }
            eph2pos(t, nav.eph + j, rs, &dts, &var);
            double toe = time2gpst(nav.eph[j].toe, &wk);
            printf("%s %d %.3f %d %.3f %d 0 %.4f %.4f %.4f %.15e\n", id, week, tow, wk, toe,
                   sys == SYS_GAL ? nav.eph[j].code : 0, rs[0], rs[1], rs[2], dts);
        }
    }
    return 0;
}
