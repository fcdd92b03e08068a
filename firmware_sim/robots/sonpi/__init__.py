"""The SonPI's firmware: its Arduino (ATmega328) sonar and motor board (``sonar_board``) and the HC-SR04 rangers at
its pins (``hcsr04``)."""
