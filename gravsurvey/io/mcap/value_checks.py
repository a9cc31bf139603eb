"""Value checks of MCAP samples that no chunk CRC protects (top-level messages, unchecked chunks).

A damaged byte in CRC-less data decodes to a wrong value rather than an error; the samples that
:func:`gravsurvey.io.checks.damaged_values` flags are dropped and counted here.
"""

from __future__ import annotations

from gravsurvey.io.checks import damaged_values

DAMAGE_CHECK_PASSES = 4  # rounds of checks.damaged_values on CRC-less samples


def check_values(blk, role):
    """Drop the samples of CRC-less data that fail :func:`checks.damaged_values`; count them.

    The count joins ``undecodable`` (so ingestion reports it with the other dropped messages)
    and the first problem line says why.

    Parameters
    ----------
    blk : DecodedBlock or None
        One channel's samples with ``verified`` (bool (n,)) and ``log_time_ns`` set.
    role : {"imu", "altimeter", "gnss", "gradient"}

    Returns
    -------
    DecodedBlock or None
        ``blk`` itself, its arrays shortened in place when samples were dropped.
    """
    if blk is None or blk.verified is None or blk.verified.all() or len(blk.time_ns) == 0:
        return blk
    nbad, whys = 0, []
    # again after each drop: a corrupted run leaves corrupted neighbours, and a spike is only
    # recognised against neighbours that agree
    for _ in range(DAMAGE_CHECK_PASSES):
        bad, why = damaged_values(role, blk.time_ns, blk.log_time_ns, blk.values, ~blk.verified)
        if not bad.any():
            break
        nbad += int(bad.sum())
        whys.append(why)
        keep = ~bad
        blk.time_ns, blk.log_time_ns, blk.verified = (blk.time_ns[keep], blk.log_time_ns[keep], blk.verified[keep])
        blk.values = {k: v[keep] for k, v in blk.values.items()}
    if not nbad:
        return blk
    blk.value_check_dropped = nbad
    blk.undecodable += nbad
    blk.problems.insert(0, f"{nbad} samples without a chunk CRC failed the damage checks ({'; '.join(whys)})")
    return blk
