build2/obj/tests/unit/test_imgio.o: tests/unit/test_imgio.c \
 common/image/imgio.h
common/image/imgio.h:
