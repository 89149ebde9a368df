/* The clock a core runs at under load, measured: a chain of dependent integer additions, one per
 * cycle, timed. Prints the frequency in MHz (whole_run.py uses it for the FMA peak, as the VM's
 * /proc/cpuinfo gives only the nominal clock and perf has no cycle counter here). */
#include <stdio.h>
#include <time.h>

int main(void) {
    const unsigned long iterations = 200000000UL;
    unsigned long x = 0;
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (unsigned long i = 0; i < iterations; i++) {
        __asm__ volatile("add $1, %0\n\tadd $1, %0\n\tadd $1, %0\n\tadd $1, %0\n\t"
                         "add $1, %0\n\tadd $1, %0\n\tadd $1, %0\n\tadd $1, %0"
                         : "+r"(x));
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    double s = (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
    printf("%.0f\n", 8.0 * (double)iterations / s / 1e6);
    return x == 0;
}
