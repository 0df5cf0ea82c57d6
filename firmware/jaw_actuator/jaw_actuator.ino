// Jaw actuator of the instrument: Actuonix PQ12-63-6-R linear servo on an Arduino Uno.
//
// The PQ12-R is an RC linear servo: a 50 Hz pulse of 1.0 ms = fully retracted,
// 2.0 ms = fully extended, position proportional to pulse width (20 mm stroke,
// 50 us/mm).  Power it from 6 V (not the Uno's 5 V pin) with a common ground.
//
// Two buttons (to GND, internal pull-ups): one opens, one closes.  A short press
// steps once on the rising edge of the press; a press held longer than 0.3 s
// moves continuously until released (paper, Sec. III-A).  Position limits are
// enforced here, whatever the host asks for.
//
// Serial line protocol (115200 baud, ASCII, lines end in '\n'); see README.md.
//   after reset  -> READY <version> <closed_us> <open_us> <pos_us>
//   PING         -> PONG
//   GET          -> OK <pos_us>
//   OPEN / CLOSE -> OK <pos_us>
//   SET <us>     -> OK <pos_us>   or LIMIT <pos_us> when clipped to a limit
//   STEP <n>     -> OK <pos_us>   or LIMIT <pos_us>   (n in us, > 0 toward open)
//   anything else-> ERR <reason>
//   buttons      -> POS <pos_us>  or POS <pos_us> LIMIT   (unsolicited)

#include <Servo.h>

const int PROTOCOL_VERSION = 1;
const uint8_t SERVO_PIN = 9;
const uint8_t BTN_OPEN_PIN = 2;
const uint8_t BTN_CLOSE_PIN = 3;

// The PQ12-R's pulse range: 1.0 ms fully retracted .. 2.0 ms fully extended.
const int PULSE_MIN_US = 1000;
const int PULSE_MAX_US = 2000;

// Firmware position limits (pulse width, us): the jaw mechanism's closed and open ends.
const int CLOSED_US = 1100;
const int OPEN_US = 1900;
const int START_US = 1100;
const int STEP_US = 50;                    // one short press: 1 mm of rod travel
const unsigned long LONG_PRESS_MS = 300;   // held longer than this: continuous motion
const unsigned long CONT_PERIOD_MS = 20;   // continuous motion: one increment per period ...
const int CONT_STEP_US = 15;               // ... 15 us / 20 ms = 15 mm/s, the actuator's no-load speed
const unsigned long DEBOUNCE_MS = 20;
const uint8_t LINE_MAX = 32;

const int LO_US = CLOSED_US < OPEN_US ? CLOSED_US : OPEN_US;
const int HI_US = CLOSED_US < OPEN_US ? OPEN_US : CLOSED_US;
const int OPEN_DIR = OPEN_US > CLOSED_US ? 1 : -1;

// Servo clamps to the attach() range without telling us, so limits outside it would make the
// reported position lie about the pulse actually sent.
static_assert(PULSE_MIN_US <= LO_US && HI_US <= PULSE_MAX_US, "CLOSED_US/OPEN_US outside the PQ12-R pulse range");
static_assert(LO_US <= START_US && START_US <= HI_US, "START_US outside the firmware limits");

Servo jaw;
int pos_us = START_US;

struct Button {
  uint8_t pin;
  int dir;                       // +1 opens, -1 closes
  bool stable;                   // debounced state (true = pressed)
  bool raw;
  unsigned long raw_since;
  unsigned long pressed_at;
  unsigned long last_cont;
  bool continuous;
};

Button buttons[2] = {
  {BTN_OPEN_PIN, 1, false, false, 0, 0, 0, false},
  {BTN_CLOSE_PIN, -1, false, false, 0, 0, 0, false},
};

char line[LINE_MAX + 1];
uint8_t line_len = 0;
bool line_overflow = false;

// Move to target (clipped to the limits); returns true when clipped.
bool moveTo(long target) {
  bool clipped = false;
  if (target < LO_US) { target = LO_US; clipped = true; }
  if (target > HI_US) { target = HI_US; clipped = true; }
  pos_us = (int)target;
  jaw.writeMicroseconds(pos_us);
  return clipped;
}

void reply(const char *word, int value) {
  Serial.print(word);
  Serial.print(' ');
  Serial.println(value);
}

void buttonMoved(bool clipped) {
  Serial.print("POS ");
  Serial.print(pos_us);
  Serial.println(clipped ? " LIMIT" : "");
}

// Parse a signed decimal integer ([+-]?digits); false if the text is not one.
bool parseInt(const char *s, long *out) {
  char *end;
  // strtol alone would also accept leading whitespace ("SET  5"); the protocol does not.
  const char *digits = (*s == '+' || *s == '-') ? s + 1 : s;
  if (!isdigit((unsigned char)*digits)) return false;
  long v = strtol(s, &end, 10);
  if (*end != '\0') return false;
  *out = v;
  return true;
}

void handleLine(char *s) {
  long n;
  if (strcmp(s, "PING") == 0) {
    Serial.println("PONG");
  } else if (strcmp(s, "GET") == 0) {
    reply("OK", pos_us);
  } else if (strcmp(s, "OPEN") == 0) {
    moveTo(OPEN_US);
    reply("OK", pos_us);
  } else if (strcmp(s, "CLOSE") == 0) {
    moveTo(CLOSED_US);
    reply("OK", pos_us);
  } else if (strncmp(s, "SET ", 4) == 0) {
    if (!parseInt(s + 4, &n)) { Serial.println("ERR bad number"); return; }
    reply(moveTo(n) ? "LIMIT" : "OK", pos_us);
  } else if (strncmp(s, "STEP ", 5) == 0) {
    if (!parseInt(s + 5, &n) || n < -1000 || n > 1000) { Serial.println("ERR bad number"); return; }
    reply(moveTo((long)pos_us + OPEN_DIR * n) ? "LIMIT" : "OK", pos_us);
  } else {
    Serial.print("ERR unknown command ");
    Serial.println(s);
  }
}

void readSerial() {
  while (Serial.available() > 0) {
    char c = (char)Serial.read();
    if (c == '\r') continue;
    if (c == '\n') {
      if (line_overflow) {
        Serial.println("ERR line too long");
      } else if (line_len > 0) {
        line[line_len] = '\0';
        handleLine(line);
      }
      line_len = 0;
      line_overflow = false;
    } else if (line_len < LINE_MAX) {
      line[line_len++] = c;
    } else {
      line_overflow = true;
    }
  }
}

void updateButton(Button &b, unsigned long now, bool other_pressed) {
  bool raw = digitalRead(b.pin) == LOW;
  if (raw != b.raw) { b.raw = raw; b.raw_since = now; }
  if (now - b.raw_since < DEBOUNCE_MS || raw == b.stable) {
    // no debounced change: a held press turns continuous after LONG_PRESS_MS
    if (b.stable && !other_pressed) {
      if (!b.continuous && now - b.pressed_at > LONG_PRESS_MS) {
        b.continuous = true;
        b.last_cont = now;
      }
      if (b.continuous && now - b.last_cont >= CONT_PERIOD_MS) {
        b.last_cont += CONT_PERIOD_MS;
        int before = pos_us;
        bool clipped = moveTo((long)pos_us + (long)b.dir * OPEN_DIR * CONT_STEP_US);
        if (pos_us != before || clipped) buttonMoved(clipped);
      }
    }
    return;
  }
  b.stable = raw;
  if (raw) {                       // rising edge of the press: one step
    b.pressed_at = now;
    b.continuous = false;
    if (!other_pressed) buttonMoved(moveTo((long)pos_us + (long)b.dir * OPEN_DIR * STEP_US));
  } else {
    b.continuous = false;
  }
}

void setup() {
  pinMode(BTN_OPEN_PIN, INPUT_PULLUP);
  pinMode(BTN_CLOSE_PIN, INPUT_PULLUP);
  // Set the pulse width before attach() starts pulsing: otherwise the first pulses could carry
  // Servo's default 1500 us and jerk the jaw half open at power-up.
  moveTo(START_US);
  jaw.attach(SERVO_PIN, PULSE_MIN_US, PULSE_MAX_US);
  Serial.begin(115200);
  Serial.print("READY ");
  Serial.print(PROTOCOL_VERSION);
  Serial.print(' ');
  Serial.print(CLOSED_US);
  Serial.print(' ');
  Serial.print(OPEN_US);
  Serial.print(' ');
  Serial.println(pos_us);
}

void loop() {
  unsigned long now = millis();
  readSerial();
  updateButton(buttons[0], now, buttons[1].stable);
  updateButton(buttons[1], now, buttons[0].stable);
}
