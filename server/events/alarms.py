"""The device's alarm codes (Alarm.code); the seed's return codes are the negative ones."""

LOCK_HOLDER_LOST = 101    # the lock holder's session ended: stopped, powered down, released
ESTOP = 102               # the e-stop was pressed
CONTROLLER = 103          # the controller reported an error
MOTION = 104              # a motion failed, or ended with a warning
CONTROLLER_LOST = 105     # the controller's process died or fell silent; Reset restarts it
OVERFLOW = 106            # a bounded queue overflowed (what was dropped is said)
PANIC = 107               # a compliant motion panicked (force or travel beyond its envelope)
DIGITAL_IO = 108          # a signalDigitalIO watch fired (its callback type CLIENT_ALARM)
PLANNING_LOST = 109        # the planning process died: its job failed, another one started
STORAGE = 110             # stored paths or settings could not be read or written (which, where)
AUDIT = 111               # the audit log could not be written: commands that move are refused
