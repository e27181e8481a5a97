/* A stand-in for the bcryptprimitives.dll of Windows 10 and later, which Wine 8 lacks: Rust's
 * standard library takes its random numbers (HashMap keys) from ProcessPrng in that DLL. Built by
 * `cargo xtask windows` next to a copy of tribo.exe for the Wine smoke test only; never shipped (a
 * real Windows has the real DLL). It draws from RtlGenRandom (advapi32's SystemFunction036). */
#include <windows.h>

BOOLEAN WINAPI SystemFunction036(PVOID buffer, ULONG length);

__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len)
{
    while (len > 0) {
        ULONG n = len > 0x40000000 ? 0x40000000 : (ULONG)len;
        if (!SystemFunction036(data, n))
            return FALSE;
        data += n;
        len -= n;
    }
    return TRUE;
}
