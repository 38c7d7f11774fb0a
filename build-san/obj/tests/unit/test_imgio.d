build-san/obj/tests/unit/test_imgio.o: tests/unit/test_imgio.c \
 common/imgio.h
common/imgio.h:
